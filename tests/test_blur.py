"""Tests of dicblur.blur against independent computations (literal loops, closed forms)."""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose
from scipy import special

from dicblur import (
    AcceleratedMotion,
    InputError,
    SineMotion,
    blur_length,
    load_image,
    motion_blur,
    render_blurred,
    save_image,
    speckle_pattern,
    trajectory_positions,
    valid_region,
)
from dicblur.cli import main
from helpers.blur import smooth_fine


@pytest.fixture(scope="module")
def pattern() -> np.ndarray:
    return speckle_pattern((64, 64), speckle_size=4, softness=0.7, seed=3)


def _cosine(shape: tuple[int, int], ky: int, kx: int, phase: float = 0.3) -> np.ndarray:
    y, x = np.indices(shape, dtype=float)
    return np.cos(2 * np.pi * (ky * y / shape[0] + kx * x / shape[1]) + phase)


def _measured_shift(ref: np.ndarray, moved: np.ndarray, fmax: float = 0.08) -> np.ndarray:
    """Translation (dy, dx) of `moved` w.r.t. `ref` from the slope of the cross-power phase
    (phase correlation) at low frequencies, weighted least squares."""
    a, b = np.fft.fft2(ref), np.fft.fft2(moved)
    fy = np.fft.fftfreq(ref.shape[0])[:, None] + 0 * a.real
    fx = np.fft.fftfreq(ref.shape[1])[None, :] + 0 * a.real
    cross = b * np.conj(a)
    keep = (np.hypot(fy, fx) < fmax) & (np.hypot(fy, fx) > 0)
    w = np.sqrt(np.abs(cross[keep]))
    phase = np.angle(cross[keep])
    design = -2 * np.pi * np.stack([fy[keep], fx[keep]], axis=1)
    sol, *_ = np.linalg.lstsq(design * w[:, None], phase * w, rcond=None)
    return sol


# ------------------------------------------------------------------ Algorithm 1 equality
MOTIONS = [(0.0, 0.0), (0.3, 0.45), (2.5, 2.5), (-3.7, 1.2), (12.3, -10.8), (0.0, 3.5)]


@pytest.mark.parametrize("motion", MOTIONS)
@pytest.mark.parametrize("shape", [(64, 64), (63, 50)])
def test_fft_equals_literal_loop(pattern: np.ndarray, motion, shape) -> None:
    img = pattern[: shape[0], : shape[1]]
    fast = motion_blur(img, motion, substeps=100)
    loop = motion_blur(img, motion, substeps=100, method="loop")
    rng = float(np.ptp(img))
    assert np.abs(fast - loop).max() <= 1e-12 * rng


@pytest.mark.parametrize(
    ("motion", "substeps"),
    [((12.3, -10.8), 5), ((0.3, 0.45), 1), ((-250.3, 120.9), 100), ((7.0, 0.5), 7)],
)
def test_fft_equals_loop_for_few_substeps(pattern: np.ndarray, motion, substeps) -> None:
    # |dy| + |dx| > K leaves the compiled kernel's range: the range-reduced closed form
    # is used instead (and at K = 7 with |dy| + |dx| = 7.5, its boundary).
    fast = motion_blur(pattern, motion, substeps=substeps)
    loop = motion_blur(pattern, motion, substeps=substeps, method="loop")
    assert np.abs(fast - loop).max() <= 1e-12 * np.ptp(pattern)


@settings(max_examples=40, deadline=None)
@given(
    rows=st.integers(2, 17),
    cols=st.integers(2, 17),
    dy=st.floats(-30, 30),
    dx=st.floats(-30, 30),
    substeps=st.integers(1, 60),
    seed=st.integers(0, 2**16),
)
def test_fft_equals_loop_property(rows, cols, dy, dx, substeps, seed) -> None:
    img = np.random.default_rng(seed).random((rows, cols)) * 255
    fast = motion_blur(img, (dy, dx), substeps=substeps)
    loop = motion_blur(img, (dy, dx), substeps=substeps, method="loop")
    assert np.abs(fast - loop).max() <= 1e-12 * max(np.ptp(img), 1.0)


def test_odd_size_equals_complex_transcription_of_paper() -> None:
    # Odd sizes have no Nyquist bin: the paper's step 7-8 (complex spectrum times
    # exp(-2 pi i f.p), inverse FFT) is real, and our result must equal it.
    img = np.random.default_rng(1).random((33, 45)) * 255
    motion = np.array([2.3, -4.1])
    k = 20
    s = np.fft.fft2(img)
    fy = np.fft.fftfreq(33)[:, None]
    fx = np.fft.fftfreq(45)[None, :]
    acc = np.zeros(img.shape, complex)
    for j in range(k + 1):
        p = j * motion / k
        acc += np.fft.ifft2(s * np.exp(-2j * np.pi * (fy * p[0] + fx * p[1])))
    acc /= k + 1
    assert np.abs(acc.imag).max() < 1e-12
    assert_allclose(motion_blur(img, motion, substeps=k), acc.real, rtol=0, atol=1e-11)


def test_discrete_blur_of_cosine_equals_spatial_sum() -> None:
    # Independent of any FFT: the average of shifted cosines is computed in real space.
    shape = (48, 40)
    ky, kx = 5, -7
    motion = np.array([3.3, 6.1])
    k = 17
    y, x = np.indices(shape, dtype=float)
    expected = np.mean(
        [
            np.cos(2 * np.pi * (ky * (y - p[0]) / shape[0] + kx * (x - p[1]) / shape[1]) + 0.3)
            for p in (np.arange(k + 1)[:, None] / k * motion)
        ],
        axis=0,
    )
    out = motion_blur(_cosine(shape, ky, kx), motion, substeps=k)
    assert_allclose(out, expected, rtol=0, atol=1e-12)


def test_integer_shift_is_exact_roll_on_even_image(pattern: np.ndarray) -> None:
    out = motion_blur(pattern, None, trajectory=np.array([[3.0, -5.0]]))
    assert_allclose(out, np.roll(pattern, (3, -5), axis=(0, 1)), rtol=0, atol=1e-10)


def test_shifts_compose_except_at_nyquist(pattern: np.ndarray) -> None:
    a, b = np.array([0.37, 1.61]), np.array([1.2, -0.45])
    odd = pattern[:63, :61]  # no Nyquist bin: sub-pixel shifts compose exactly
    one = motion_blur(motion_blur(odd, None, trajectory=[a]), None, trajectory=[b])
    assert_allclose(one, motion_blur(odd, None, trajectory=[a + b]), rtol=0, atol=1e-10)
    # Even size: they compose except for the Nyquist rows/cols, which lose a factor
    # cos(pi a) cos(pi b) / cos(pi (a + b)); the difference lives only in those bins.
    one = motion_blur(motion_blur(pattern, None, trajectory=[a]), None, trajectory=[b])
    diff = np.fft.rfft2(one - motion_blur(pattern, None, trajectory=[a + b]))
    diff[32, :] = 0
    diff[:, -1] = 0
    assert np.abs(diff).max() < 1e-8


def test_nyquist_corner_uses_symmetric_split() -> None:
    # A checkerboard is the pure corner (Nyquist, Nyquist) component. Shifted by half a px
    # along each axis, the symmetric band-limited interpolant cos(pi y) cos(pi x) is zero
    # at every pixel; the real part of a complex inverse FFT would give cos(pi) = -1.
    y, x = np.indices((8, 8))
    board = (-1.0) ** (y + x)
    out = motion_blur(board, None, trajectory=[[0.5, 0.5]])
    assert_allclose(out, 0.0, atol=1e-14)
    # Along one axis only, both conventions agree: cos(pi * 0.25) times the board.
    out = motion_blur(board, None, trajectory=[[0.25, 0.0]])
    assert_allclose(out, math.cos(math.pi * 0.25) * board, atol=1e-14)


def test_output_is_real_and_float64(pattern: np.ndarray) -> None:
    out = motion_blur(pattern.astype(np.uint8), (0.7, 1.9))
    assert out.dtype == np.float64 and out.shape == pattern.shape


# ------------------------------------------------------------------ position, limits
@pytest.mark.parametrize("motion", [(0.0, 3.0), (2.0, -1.5), (0.8, 0.6)])
def test_mean_position_is_half_motion(pattern: np.ndarray, motion) -> None:
    out = motion_blur(pattern, motion)
    assert_allclose(_measured_shift(pattern, out), np.array(motion) / 2, atol=2e-3)


def test_acceleration_from_rest_mean_position_is_one_third(pattern: np.ndarray) -> None:
    # p(t) = X t^2, mean over t in [0, 1] = X / 3 (continuous limit).
    motion = (0.0, 3.0)
    out = motion_blur(pattern, motion, substeps=None, trajectory="acceleration")
    # The kernel is skewed: keep only the lowest frequencies, where the phase slope is the
    # first moment (the third cumulant adds < 1e-3 px at |f| = 1/64).
    assert_allclose(_measured_shift(pattern, out, fmax=0.02), [0.0, 1.0], atol=2e-3)


def test_continuous_linear_equals_analytic_sinc() -> None:
    shape = (40, 64)
    for ky, kx in [(3, 5), (-7, 11), (0, 32)]:
        motion = np.array([2.7, -4.4])
        phi = ky / shape[0] * motion[0] + kx / shape[1] * motion[1]
        y, x = np.indices(shape, dtype=float)
        expected = np.sinc(phi) * np.cos(
            2 * np.pi * (ky * y / shape[0] + kx * x / shape[1]) + 0.3 - np.pi * phi
        )
        if kx == 32:  # Nyquist column: symmetric split keeps the sampled cosine real
            expected = np.sinc(phi) * np.cos(np.pi * phi) * _cosine(shape, ky, kx, 0.0)
            out = motion_blur(_cosine(shape, ky, kx, 0.0), motion, substeps=None)
        else:
            out = motion_blur(_cosine(shape, ky, kx), motion, substeps=None)
        assert_allclose(out, expected, rtol=0, atol=1e-12)


def test_discrete_converges_to_continuous(pattern: np.ndarray) -> None:
    cont = motion_blur(pattern, (1.5, 4.0), substeps=None)
    e100 = np.abs(motion_blur(pattern, (1.5, 4.0), substeps=100) - cont).max()
    e1000 = np.abs(motion_blur(pattern, (1.5, 4.0), substeps=1000) - cont).max()
    assert e1000 < e100 / 8  # O(1/K)


@pytest.mark.parametrize(("amp", "cycles"), [((1.2, 2.5), 1.0), ((20.0, -35.0), 3.0)])
def test_sine_full_cycles_equal_bessel_j0(amp, cycles) -> None:
    # mean over whole cycles of cos(a - b sin(2 pi c t + phase)) = J0(b) cos(a).
    shape = (32, 48)
    amp = np.array(amp)
    ky, kx = 3, 4
    b = 2 * np.pi * (ky / shape[0] * amp[0] + kx / shape[1] * amp[1])
    img = _cosine(shape, ky, kx)
    out = motion_blur(img, amp, substeps=None, trajectory=SineMotion(cycles=cycles, phase=0.4))
    assert_allclose(out, special.j0(b) * img, rtol=0, atol=1e-12)


@pytest.mark.parametrize("substeps", [100, None])
def test_zero_amplitude_sine_is_identity(pattern: np.ndarray, substeps) -> None:
    out = motion_blur(
        pattern, (0.0, 0.0), substeps=substeps, trajectory=SineMotion(cycles=3.3, phase=1.0)
    )
    assert_allclose(out, pattern, rtol=0, atol=1e-10)


def test_path_array_callable_and_linear_agree(pattern: np.ndarray) -> None:
    motion = np.array([-2.2, 5.3])
    t = np.arange(101) / 100
    by_array = motion_blur(pattern, None, trajectory=t[:, None] * motion)
    by_callable = motion_blur(pattern, None, trajectory=lambda s: s[:, None] * motion)
    linear = motion_blur(pattern, motion)
    assert_allclose(by_array, linear, rtol=0, atol=1e-10)
    assert_allclose(by_callable, linear, rtol=0, atol=1e-10)


def test_preset_positions() -> None:
    m = np.array([1.0, 2.0])
    pos, w = trajectory_positions(m, substeps=4, trajectory=AcceleratedMotion(start_speed=0.0))
    assert_allclose(pos, (np.arange(5) / 4)[:, None] ** 2 * m)
    assert_allclose(w.sum(), 1.0)
    pos, _ = trajectory_positions(m, substeps=4, trajectory="sine")
    assert_allclose(pos[:, 1], 2.0 * np.sin(2 * np.pi * np.arange(5) / 4), atol=1e-15)
    pos, w = trajectory_positions(m, substeps=None, trajectory="sine")
    assert_allclose(w.sum(), 1.0)
    assert pos.shape[1] == 2 and pos.shape[0] >= 64


def test_loop_general_trajectory_matches_fft(pattern: np.ndarray) -> None:
    traj = SineMotion(cycles=0.7, phase=0.2)
    a = motion_blur(pattern, (1.1, 2.9), trajectory=traj, substeps=40)
    b = motion_blur(pattern, (1.1, 2.9), trajectory=traj, substeps=40, method="loop")
    assert np.abs(a - b).max() <= 1e-12 * np.ptp(pattern)


# ------------------------------------------------------------------ boundaries
def test_reflect_removes_wraparound_on_ramp() -> None:
    img = np.add.outer(np.arange(128.0) * 0.5, np.arange(128.0))
    motion = (2.3, 5.6)
    truth = img - 0.5 * motion[0] * 0.5 - 0.5 * motion[1]  # a ramp moved by motion / 2
    rows, cols = valid_region(img.shape, motion)
    assert (rows.start, cols.start) == (5, 8)  # ceil(2.3) + 2, ceil(5.6) + 2
    reflect = motion_blur(img, motion, boundary="reflect")
    periodic = motion_blur(img, motion)
    assert np.abs(reflect - truth)[rows, cols].max() < 2e-3
    assert np.abs(periodic - truth)[rows, cols].max() > 0.1  # the wrapped seam rings


def test_reflect_loop_equals_fft(pattern: np.ndarray) -> None:
    a = motion_blur(pattern[:40, :30], (1.7, -2.2), boundary="reflect", substeps=30)
    b = motion_blur(pattern[:40, :30], (1.7, -2.2), boundary="reflect", substeps=30, method="loop")
    assert np.abs(a - b).max() <= 1e-12 * np.ptp(pattern)


def test_valid_region_negative_motion() -> None:
    rows, cols = valid_region((100, 80), (-3.5, 0.0), guard=0)
    assert (rows.start, rows.stop, cols.start, cols.stop) == (0, 96, 0, 80)


# ------------------------------------------------------------------ rendering
def test_render_converges_to_fourier_for_smooth_pattern() -> None:
    n, motion = 32, (1.3, 2.7)
    errors = []
    for ss in (2, 4, 8, 16):
        fine = smooth_fine(n, ss)
        camera = fine.reshape(n, ss, n, ss).mean(axis=(1, 3))
        rendered = render_blurred(fine, motion, supersample=ss)
        errors.append(np.abs(rendered - motion_blur(camera, motion, substeps=None)).max())
    assert all(b < a * 0.6 for a, b in itertools.pairwise(errors))
    assert errors[-1] < 0.2  # grey levels, on a 200 GL range


def test_render_differs_from_fourier_for_hard_edges() -> None:
    # Not band-limited: Fourier shifting the binned image is not the moving pattern.
    n, ss, motion = 32, 8, (1.3, 2.7)
    fine = speckle_pattern((n * ss, n * ss), speckle_size=3 * ss, seed=1)
    camera = fine.reshape(n, ss, n, ss).mean(axis=(1, 3))
    diff = render_blurred(fine, motion, supersample=ss) - motion_blur(camera, motion, substeps=None)
    assert np.sqrt(np.mean(diff**2)) > 2.0


def test_render_integer_motion_supersample_one_is_roll_average() -> None:
    img = np.random.default_rng(2).random((16, 16))
    out = render_blurred(img, None, supersample=1, trajectory=[[0, 0], [0, 1], [0, 2]])
    expected = (img + np.roll(img, 1, axis=1) + np.roll(img, 2, axis=1)) / 3
    assert_allclose(out, expected, atol=1e-15)


# ------------------------------------------------------------------ blur_length
def test_blur_length() -> None:
    assert blur_length(100.0, 1e-3, 0.05) == pytest.approx(2.0)
    assert blur_length(-100.0, 1e-3, 0.05) == pytest.approx(2.0)
    with pytest.raises(InputError, match="scale"):
        blur_length(1.0, 1.0, 0.0)
    with pytest.raises(InputError, match="exposure"):
        blur_length(1.0, -1.0, 1.0)


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"motion": (float("nan"), 1.0)}, "motion"),
        ({"motion": (1.0, 2.0, 3.0)}, "motion"),
        ({"motion": (0.0, 1.0), "substeps": -3}, "substeps=-3"),
        ({"motion": (0.0, 1.0), "substeps": 2.5}, "substeps"),
        ({"motion": (0.0, 1.0), "trajectory": "zigzag"}, "trajectory"),
        ({"motion": (0.0, 1.0), "trajectory": 3.0}, "trajectory"),
        ({"motion": (0.0, 1.0), "boundary": "wrap"}, "boundary"),
        ({"motion": (0.0, 1.0), "method": "slow"}, "method"),
        ({"motion": (0.0, 1.0), "substeps": None, "method": "loop"}, "finite substeps"),
        ({"motion": (0.0, 1.0), "trajectory": np.zeros((5, 2))}, "motion=None"),
        ({"motion": None, "trajectory": np.zeros((5, 3))}, r"\(K \+ 1, 2\)"),
        ({"motion": None, "trajectory": lambda t: t}, "callable"),
    ],
)
def test_bad_blur_arguments(pattern: np.ndarray, kwargs, match) -> None:
    motion = kwargs.pop("motion")
    with pytest.raises(InputError, match=match):
        motion_blur(pattern, motion, **kwargs)


def test_bad_images() -> None:
    bad = np.ones((8, 8))
    bad[2, 3] = np.nan
    with pytest.raises(InputError, match="NaN"):
        motion_blur(bad, (0.0, 1.0))
    with pytest.raises(InputError, match="2-D"):
        motion_blur(np.ones(16), (0.0, 1.0))
    with pytest.raises(InputError, match="multiple of supersample"):
        render_blurred(np.ones((10, 10)), (0.0, 1.0), supersample=3)


# ------------------------------------------------------------------ CLI
def test_cli_blur_writes_image_and_is_reproducible(tmp_path, capsys) -> None:
    src = tmp_path / "p.tif"
    save_image(src, speckle_pattern((48, 48), speckle_size=4, softness=0.5, seed=1))
    outs = []
    for name in ("a.tif", "b.tif"):
        rc = main(
            [
                "blur",
                str(src),
                str(tmp_path / name),
                "--length",
                "3.5",
                "--angle",
                "30",
                "--noise",
                "2",
                "--seed",
                "7",
            ]
        )
        assert rc == 0
        outs.append((tmp_path / name).read_bytes())
    assert outs[0] == outs[1]
    meta = json.loads((tmp_path / "a.tif.json").read_text())
    assert_allclose(meta["motion_dy_dx_px"], [1.75, 3.5 * math.cos(math.pi / 6)])
    # Noise-free, no quantisation beyond 8 bits: equals the library call, rounded.
    rc = main(
        [
            "blur",
            str(src),
            str(tmp_path / "c.tif"),
            "--length",
            "2",
            "--trajectory",
            "sine",
            "--cycles",
            "0.5",
        ]
    )
    assert rc == 0
    expected = np.clip(
        np.rint(motion_blur(load_image(src), (0.0, 2.0), trajectory=SineMotion(cycles=0.5))), 0, 255
    )
    assert_allclose(load_image(tmp_path / "c.tif"), expected)
    capsys.readouterr()


@pytest.mark.parametrize(
    "extra",
    [
        ["--length", "nan"],
        ["--length", "2", "--trajectory", "zigzag"],
        ["--length", "2", "--substeps", "-1"],
        ["--length", "2", "--noise", "2", "--full-well", "1000"],
        ["--length", "2", "--bit-depth", "12"],
        ["--length", "2", "--boundary", "wrap"],
    ],
)
def test_cli_blur_bad_input_exit_2(tmp_path, capsys, extra) -> None:
    src = tmp_path / "p.tif"
    save_image(src, np.full((16, 16), 100.0))
    rc = main(["blur", str(src), str(tmp_path / "o.tif"), *extra])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith("error:") and "Traceback" not in err
    assert not (tmp_path / "o.tif").exists()


def test_cli_blur_missing_image_exit_2(tmp_path, capsys) -> None:
    rc = main(["blur", str(tmp_path / "none.tif"), str(tmp_path / "o.tif"), "--length", "2"])
    assert rc == 2
    assert "Traceback" not in capsys.readouterr().err
