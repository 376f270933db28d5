"""Code the tests share: ``helpers.campaign`` (a cheap real campaign task, spec builders,
the numba cache warm-up), ``helpers.dic`` (synthetic DIC images), ``helpers.models``
(synthetic model data with known parameters, the direct simulation) and ``helpers.cli``
(the command lines several CLI tests run). Benchmarks that measure what a test checks
import them too (``benchmarks/_harness.use_tests_dir``).

pytest puts ``tests/`` on ``sys.path`` (rootdir conftest, prepend import mode), so test
modules import these as ``from helpers.campaign import ...`` with no path edits.
"""
