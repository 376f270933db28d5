"""Blur-compensated correlation (issue 18): forward model, estimation, baseline, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

import dicblur
from dicblur.blur import motion_blur
from dicblur.dic import Correlator
from dicblur.dic.compensation import blur_reference, deblur_wiener
from dicblur.errors import InputError

ROI = (8, 104, 8, 104)


@pytest.fixture(scope="module")
def ref() -> np.ndarray:
    return dicblur.speckle_pattern((112, 112), speckle_size=5, seed=3, softness=1.0)


def _blurred(ref: np.ndarray, d0: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Target moving from d0 to d0 + x (dy, dx px) during the exposure, continuous."""
    return motion_blur(
        ref, None, substeps=None, trajectory=lambda t: d0[None, :] + t[:, None] * x[None, :]
    )


def _vector(length: float, angle_deg: float) -> np.ndarray:
    a = math.radians(angle_deg)
    return length * np.array([math.sin(a), math.cos(a)])


@pytest.mark.parametrize("shape", ["translation", "affine"])
@pytest.mark.parametrize("angle", [0.0, 30.0])
def test_given_blur_returns_mean_position(ref: np.ndarray, shape: str, angle: float) -> None:
    # mean position during the exposure at whole px: no interpolation bias, so what is
    # left is the blur mismatch (plain) or nothing (compensated)
    x = _vector(6.0, angle)
    mean = np.array([1.0, 2.0])
    cur = _blurred(ref, mean - x / 2, x)
    kw = {"subset": 31, "step": 16, "shape": shape, "roi": ROI}
    plain = Correlator(ref, **kw).correlate(cur)
    comp = Correlator(ref, blur="given", **kw).correlate(cur, blur_vector=x)
    assert comp.converged.all()
    err_c = max(np.abs(comp.u - mean[1]).max(), np.abs(comp.v - mean[0]).max())
    ok = plain.converged
    err_p = max(np.abs(plain.u[ok] - mean[1]).max(), np.abs(plain.v[ok] - mean[0]).max())
    assert err_c < 1e-4
    assert err_p > 0.01  # the mismatch the compensation removes
    assert comp.info["blur_compensation"] == "given"


@pytest.mark.parametrize("shape", ["translation", "affine"])
def test_zero_blur_equals_plain(ref: np.ndarray, shape: str) -> None:
    cur = np.roll(ref, (1, 2), axis=(0, 1)) + 0.5 * np.sin(np.arange(112.0))[None, :]
    kw = {"subset": 21, "step": 12, "shape": shape, "roi": ROI, "noise_sigma": 1.0}
    a = Correlator(ref, **kw).correlate(cur)
    b = Correlator(ref, blur="given", **kw).correlate(cur, blur_vector=(0.0, 0.0))
    assert np.array_equal(a.params, b.params, equal_nan=True)
    assert np.array_equal(a.status, b.status)
    assert np.array_equal(a.predicted_sigma_u, b.predicted_sigma_u, equal_nan=True)
    # a vanishing blur vector goes through the blurred reference: equal within rounding
    c = Correlator(ref, blur="given", **kw).correlate(cur, blur_vector=(0.0, 1e-9))
    assert np.nanmax(np.abs(c.params - a.params)) < 1e-6


def test_per_point_vectors_match_single(ref: np.ndarray) -> None:
    x = _vector(4.0, 0.0)
    cur = _blurred(ref, np.array([1.0, 0.0]), x)
    kw = {"subset": 31, "step": 16, "shape": "translation", "roi": ROI}
    c = Correlator(ref, blur="given", **kw)
    one = c.correlate(cur, blur_vector=x)
    per = np.tile(x, (c.n_points, 1))
    per[::2] = _vector(3.0, 0.0)
    mixed = c.correlate(cur, blur_vector=per)
    assert mixed.info["blur_vectors"] == 2
    odd = np.arange(c.n_points) % 2 == 1
    assert np.allclose(mixed.u[odd], one.u[odd], atol=1e-6)
    # the wrong blur length leaves a mismatch on the other half
    assert np.abs(mixed.u[~odd] - 2.0).max() > 10 * np.abs(one.u[~odd] - 2.0).max()


def test_bad_blur_vectors(ref: np.ndarray) -> None:
    cur = ref.copy()
    c = Correlator(ref, subset=21, step=20, shape="translation", blur="given")
    with pytest.raises(InputError, match="finite"):
        c.correlate(cur, blur_vector=(0.0, float("nan")))
    with pytest.raises(InputError, match="shorter than the subset"):
        c.correlate(cur, blur_vector=(0.0, 21.0))
    with pytest.raises(InputError, match="shape"):
        c.correlate(cur, blur_vector=np.zeros((3, 2)))
    with pytest.raises(InputError, match="blur='given' needs"):
        c.correlate(cur)
    with pytest.raises(InputError, match="blur_angle"):
        c.correlate(cur, blur_vector=(0.0, 2.0), blur_angle=30.0)
    plain = Correlator(ref, subset=21, step=20, shape="translation")
    with pytest.raises(InputError, match="blur='none'"):
        plain.correlate(cur, blur_vector=(0.0, 2.0))
    est = Correlator(ref, subset=21, step=20, shape="translation", blur="estimate")
    with pytest.raises(InputError, match="direction"):
        est.correlate(cur)
    with pytest.raises(InputError, match="blur="):
        Correlator(ref, blur="maybe")  # type: ignore[arg-type]


@pytest.mark.parametrize("shape", ["translation", "affine"])
def test_estimate_recovers_blur(ref: np.ndarray, shape: str) -> None:
    x = _vector(4.6, 30.0)
    mean = np.array([1.0, 2.0])
    cur = _blurred(ref, mean - x / 2, x)
    c = Correlator(ref, subset=31, step=16, shape=shape, roi=ROI, blur="estimate")
    res = c.correlate(cur, blur_angle=30.0)
    assert res.blur_length is not None and res.blur_identified is not None
    assert res.blur_identified.all()
    assert np.abs(res.blur_length - 4.6).max() < 0.01
    assert np.abs(res.u - mean[1]).max() < 1e-3
    assert np.abs(res.v - mean[0]).max() < 1e-3
    # the direction may come from a vector, whose length only starts the search
    res2 = c.correlate(cur, blur_vector=_vector(2.0, 30.0))
    assert np.abs(res2.blur_length - 4.6).max() < 0.01
    # the next image starts from this one's length and follows a changed blur
    x3 = _vector(6.3, 30.0)
    res3 = c.correlate(_blurred(ref, mean - x3 / 2, x3), blur_angle=30.0)
    assert res3.blur_length is not None
    assert np.abs(res3.blur_length - 6.3).max() < 0.01
    assert np.abs(res3.u - mean[1]).max() < 1e-3


def test_estimate_flags_unidentifiable_blur() -> None:
    rng = np.random.default_rng(5)
    kw = {
        "subset": 21,
        "step": 10,
        "shape": "translation",
        "blur": "estimate",
        "max_blur_sigma": 0.1,
    }
    out = []
    for contrast in (1.0, 0.1):
        ref = dicblur.speckle_pattern(
            (128, 128), speckle_size=5, seed=4, softness=1.0, contrast=contrast
        )
        x = np.array([0.0, 4.0])
        cur = _blurred(ref, np.array([0.0, -2.0]), x) + rng.normal(0.0, 2.0, ref.shape)
        res = Correlator(ref + rng.normal(0.0, 2.0, ref.shape), **kw).correlate(cur, blur_vector=x)
        assert res.blur_identified is not None and res.blur_sigma is not None
        assert res.blur_length is not None
        ok = np.isfinite(res.blur_length)
        out.append(
            (res.blur_identified.mean(), np.std(res.blur_length[ok]), np.mean(res.blur_sigma[ok]))
        )
    assert out[0][0] > 0.9  # 255 GL contrast: the blur length is measured per subset
    assert out[1][0] < 0.2  # 25 GL contrast against 2 GL noise: too little texture
    # the stated standard error is the scatter of the estimates
    for _, spread, sigma in out:
        assert 0.6 < spread / sigma < 1.6


def test_blur_reference_derivative_and_model() -> None:
    img = dicblur.speckle_pattern((64, 64), speckle_size=4, seed=1, softness=0.8)
    x = _vector(3.0, 30.0)
    b, d = blur_reference(img, x, derivative=True)
    h = 1e-4
    bp, _ = blur_reference(img, x * (1 + h / 3.0))
    bm, _ = blur_reference(img, x * (1 - h / 3.0))
    assert d is not None
    assert np.abs((bp - bm) / (2 * h) - d).max() < 1e-5 * np.abs(d).max()
    # the centred box is Algorithm 1 (continuous) from -X/2 to +X/2, mirror boundary
    alg = motion_blur(
        img,
        None,
        substeps=None,
        boundary="reflect",
        trajectory=lambda t: (t[:, None] - 0.5) * x[None, :],
    )
    assert np.abs(b - alg).max() < 1e-9


def test_deblur_wiener_restores() -> None:
    img = dicblur.speckle_pattern((96, 96), speckle_size=5, seed=2, softness=1.0)
    x = np.array([0.0, 6.0])
    blurred, _ = blur_reference(img, x)
    inner = (slice(12, -12), slice(12, -12))
    restored = deblur_wiener(blurred, x, 0.5)
    assert np.abs(restored - img)[inner].std() < 0.3 * np.abs(blurred - img)[inner].std()
    assert np.array_equal(deblur_wiener(img, (0.0, 0.0), 1.0), img)
    with pytest.raises(InputError, match="noise_sigma"):
        deblur_wiener(img, x, -1.0)


def test_correlate_cli_blur_compensation(ref: np.ndarray, tmp_path, capsys) -> None:
    from dicblur import save_image
    from dicblur.cli import main

    x = _vector(5.0, 0.0)
    cur = _blurred(ref, np.array([1.0, 2.0]) - x / 2, x)
    save_image(tmp_path / "ref.tif", ref, bit_depth=16)
    save_image(tmp_path / "cur.tif", cur, bit_depth=16)
    base = [
        "correlate",
        str(tmp_path / "ref.tif"),
        str(tmp_path / "cur.tif"),
        "--subset",
        "31",
        "--step",
        "16",
        "--shape",
        "translation",
    ]
    out = tmp_path / "field.csv"
    assert (
        main([*base, "--blur-compensation", "given", "--blur", "5", "--angle", "0", "-o", str(out)])
        == 0
    )
    import csv

    with out.open() as fh:
        rows = [r for r in csv.DictReader(fh) if r["status_name"] == "converged"]
    inner = [r for r in rows if 24 <= int(r["row"]) <= 88 and 24 <= int(r["col"]) <= 88]
    u = np.array([float(r["u"]) for r in inner])
    assert len(u) > 0 and np.abs(u - 2.0).max() < 0.01  # 16-bit quantised images
    capsys.readouterr()
    assert main([*base, "--blur-compensation", "estimate", "--angle", "0"]) == 0
    assert "blur_length_mean" in capsys.readouterr().out
    for extra, needle in (
        (["--blur-compensation", "given"], "--blur"),
        (["--blur-compensation", "given", "--blur", "-3"], "--blur=-3"),
        (["--blur-compensation", "sometimes"], "--blur-compensation"),
        (["--blur", "3"], "only used with"),
        (["--blur-compensation", "given", "--blur", "40"], "subset"),
    ):
        assert main([*base, *extra]) == 2
        assert needle in capsys.readouterr().err


def test_predict_compensated_zero_blur_is_match_score_bound() -> None:
    from dicblur.metrics import directional_sssig
    from dicblur.models.compensated import predict_compensated

    img = dicblur.speckle_pattern((96, 96), speckle_size=4, seed=8, softness=0.5)
    p = predict_compensated(
        img, [0.0, 4.0], noise_sigma=2.0, subset=21, step=10, derivative="central"
    )
    pts = np.asarray(dicblur.subset_centres(img.shape, subset=21, step=10))
    s = directional_sssig(img, pts, subset=21, angle=0.0)
    assert p.u_e[0] == pytest.approx(math.sqrt(np.mean(2 * 4.0 / s)), rel=1e-12)
    assert np.all(p.u_blur == 0)
    # blurring lowers the reference's noise: below the blurred image's static bound
    assert p.u_e[1] < math.sqrt(2 * 4.0 / p.sssig[1])
    with pytest.raises(InputError, match="subset"):
        predict_compensated(img, [25.0], noise_sigma=2.0, subset=21)


def test_predict_compensated_against_monte_carlo() -> None:
    from dicblur.models.compensated import predict_compensated

    img = dicblur.speckle_pattern((128, 128), speckle_size=4, seed=9, softness=0.5)
    x = np.array([0.0, 6.0])
    cur = _blurred(img, np.array([0.0, -3.0]), x)
    c = Correlator(
        img, subset=21, step=6, roi=(10, 118, 10, 118), shape="translation", blur="given"
    )
    pts = np.stack([c.rows, c.cols], axis=1)
    pred = predict_compensated(img, [6.0], noise_sigma=2.0, subset=21, points=pts)
    rng = np.random.default_rng(2)
    var = []
    for _ in range(4):
        cc = Correlator(
            img + rng.normal(0, 2.0, img.shape),
            subset=21,
            step=6,
            roi=(10, 118, 10, 118),
            shape="translation",
            blur="given",
        )
        r = cc.correlate(cur + rng.normal(0, 2.0, img.shape), blur_vector=x)
        var.append(np.var(r.u[r.converged], ddof=1))
    measured = math.sqrt(np.mean(var))
    assert measured == pytest.approx(float(pred.u_e[0]), rel=0.15)


def test_campaign_sweeps_with_compensation(tmp_path) -> None:
    from dicblur.campaign import iter_batches, make_pattern, parse_spec, simulate_batch
    from dicblur.errors import ConfigError

    img = dicblur.speckle_pattern((96, 96), speckle_size=4, softness=0.7, seed=9)
    path = tmp_path / "p.tif"
    dicblur.save_image(path, img * 200.0, bit_depth=16)

    def spec(**dic: object) -> dicblur.CampaignSpec:
        return parse_spec(
            {
                "campaign": {"seed": 1},
                "pattern": [{"name": "p", "path": str(path)}],
                "blur": {"lengths": [0.0, 6.0], "boundary": "reflect"},
                "noise": {"model": "per-exposure", "levels": [2.0]},
                "dic": {"subsets": [21], "step": 8, **dic},
            }
        )

    plain, comp = spec(), spec(compensation="given")
    assert plain.content_hash() == spec(compensation="none").content_hash()
    assert comp.content_hash() != plain.content_hash()
    out = {}
    for name, s in (("plain", plain), ("given", comp), ("deblur", spec(compensation="deblur"))):
        (batch,) = iter_batches(s)
        out[name] = simulate_batch(make_pattern(s, s.patterns[0]), batch, s)
    # W = 0: the same matcher; W = 6 px: the mismatch is gone
    assert out["given"]["u_e"][0] == out["plain"]["u_e"][0]
    assert out["given"]["u_e"][1] < 0.5 * out["plain"]["u_e"][1]
    assert abs(out["given"]["bias"][1]) < 0.01
    assert out["deblur"]["u_e"][0] == out["plain"]["u_e"][0]  # no blur: nothing to deblur
    # (on this 0..51000 GL image the scalar-NSR Wiener filter is nearly the inverse
    # filter and amplifies the noise at the zeros of sinc: worse than plain here)
    assert out["given"]["u_e"][1] < 0.2 * out["deblur"]["u_e"][1]
    with pytest.raises(ConfigError, match=r"dic\.compensation"):
        spec(compensation="sometimes")
    with pytest.raises(ConfigError, match="subsets larger"):
        parse_spec(
            {
                "campaign": {"seed": 1},
                "pattern": [{"name": "p", "path": str(path)}],
                "blur": {"lengths": [0.0, 30.0]},
                "dic": {"subsets": [21], "compensation": "given"},
            }
        )


def test_pattern_predict_cli_compensation(tmp_path, capsys) -> None:
    import json

    from dicblur import save_image
    from dicblur.cli import main

    img = dicblur.speckle_pattern((96, 96), speckle_size=4, seed=8, softness=0.5)
    save_image(tmp_path / "p.tif", img, bit_depth=16)
    args = [
        "pattern",
        "predict",
        str(tmp_path / "p.tif"),
        "--noise",
        "2",
        "--subset",
        "21",
        "--step",
        "10",
        "--blur",
        "0",
        "--blur",
        "6",
    ]
    assert main([*args, "--compensation", "given", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["gain"][0] == pytest.approx(1.0, rel=0.03)  # no blur: the same matcher
    assert data["gain"][1] > 2.0  # W = 6 px: the mismatch term is gone
    # -o writes the compensated matcher's model (tests/test_models_compensation.py);
    # the compensated prediction is the aligned one
    assert main([*args, "--compensation", "given", "--subpixel", "average"]) == 2
    assert "--compensation" in capsys.readouterr().err
