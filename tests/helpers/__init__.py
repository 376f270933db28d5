"""Helpers shared by the tests: ``helpers.campaign`` (a cheap real campaign task, spec
builders, the numba cache warm-up) and ``helpers.dic`` (synthetic DIC images).

pytest puts ``tests/`` on ``sys.path`` (rootdir conftest, prepend import mode), so test
modules import these as ``from helpers.campaign import ...`` with no path edits.
"""
