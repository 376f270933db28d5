"""The reference's terms kept across blur lengths (models.reference_terms): the same
numbers as recomputing them, on any number of threads, and never another image's."""

from __future__ import annotations

import numpy as np
import pytest

from dicblur.errors import InputError
from dicblur.models import static_terms
from dicblur.models.reference_terms import ReferenceTerms
from dicblur.models.sensitivity import shifts_and_variance
from dicblur.models.subset_algebra import SubsetMatcher
from dicblur.patterns import paper_pattern4


def _run(img, reference, offset):
    pts = np.array([[r, c] for r in range(16, 64, 12) for c in range(16, 64, 12)])
    matcher = SubsetMatcher((0.0, 1.0), "translation", "bspline3", "reflect")
    lam = np.empty((3, len(pts)))
    xi, var = shifts_and_variance(
        img, [0.0, 1.5, 3.0], pts, 15, matcher, criterion="znssd", max_shift=1.0,
        chunk=7, variance=True, offset=offset, min_contraction=0.02, contraction_out=lam,
        reference=reference,
    )  # fmt: skip
    return xi, var, lam


def test_kept_terms_give_the_same_numbers_and_refuse_another_image():
    img = paper_pattern4((80, 80), seed=3)
    ref = ReferenceTerms()
    for offset in (None, 0.25, 0.75):  # the second and third calls reuse the kept terms
        plain = _run(img, None, offset)
        kept = _run(img, ref, offset)
        for a, b in zip(plain, kept, strict=True):
            assert np.array_equal(a, b, equal_nan=True)
    with pytest.raises(InputError, match="another image"):
        _run(img + 1.0, ref, None)
    # a store too small to keep anything: computed each time, same numbers
    tiny = ReferenceTerms(max_bytes=0)
    assert all(
        np.array_equal(a, b, equal_nan=True)
        for a, b in zip(_run(img, tiny, 0.5), _run(img, None, 0.5), strict=True)
    )


def test_static_terms_same_table_on_two_threads():
    img = paper_pattern4((72, 72), seed=4)
    kw = dict(subset=15, step=12, extend_to=4.0)
    one = static_terms(img, np.arange(0.25, 2.01, 0.25), threads=1, **kw)
    two = static_terms(img, np.arange(0.25, 2.01, 0.25), threads=2, **kw)
    assert one == two and len(one.blur) > 9
