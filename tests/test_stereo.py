"""Stereo geometry (issue 29): rig files, projection, undistortion, triangulation and its
propagation, the renderer's compiled ray cast, and the CLI's bad inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicblur.cli import main
from dicblur.errors import ConfigError
from dicblur.stereo import (
    CameraModel,
    StereoRig,
    load_rig,
    propagate,
    save_rig,
    triangulate,
    triangulation_jacobian,
)
from dicblur.stereo.synthetic import SpeckleTarget, symmetric_rig
from dicblur.stereo.uncertainty import ratio_out_of_plane

CAM = CameraModel(2000.0, 1990.0, 130.2, 120.7, (-0.12, 0.08, 0.002, -0.0015, 0.01), (240, 256))


def _rig(angle: float = 30.0) -> StereoRig:
    right = CameraModel(2050.0, 2040.0, 125.0, 118.0, (0.05, -0.02, -0.001, 0.001, 0.0), (240, 256))
    return symmetric_rig(stereo_angle=angle, distance=400.0, camera=CAM, right=right)


def _points(n: int = 200, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.normal([0.0, 0.0, 400.0], [8.0, 8.0, 5.0], (n, 3))


@pytest.mark.parametrize("suffix", [".json", ".yml", ".xml"])
def test_rig_round_trip(tmp_path, suffix):
    rig = _rig()
    rig = StereoRig(rig.left, rig.right, rig.rotation, rig.translation, rms=0.123)
    back = load_rig(save_rig(rig, tmp_path / f"rig{suffix}"))
    for a, b in ((rig.left, back.left), (rig.right, back.right)):
        assert a == b
    np.testing.assert_allclose(back.rotation, rig.rotation, atol=1e-15)
    np.testing.assert_allclose(back.translation, rig.translation, atol=1e-12)
    assert back.rms == pytest.approx(0.123)


def test_rig_file_errors_name_the_file(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        load_rig(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text('{"left": {}}')
    with pytest.raises(ConfigError, match=r"bad\.json"):
        load_rig(bad)


def test_undistort_inverts_distort():
    ab = np.random.default_rng(1).uniform(-0.1, 0.1, (500, 2))
    np.testing.assert_allclose(CAM.undistort(CAM.distort(ab)), ab, atol=1e-12)


def test_projection_matches_opencv():
    import cv2

    rig = _rig()
    x = _points(50)
    pl, pr = rig.project(x)
    rvec, _ = cv2.Rodrigues(rig.rotation)
    for pts, cam, rv, tv in (
        (pl, rig.left, np.zeros(3), np.zeros(3)),
        (pr, rig.right, rvec, rig.translation),
    ):
        cv, _ = cv2.projectPoints(x, rv, tv, cam.matrix, np.asarray(cam.dist))
        np.testing.assert_allclose(pts[:, ::-1], cv[:, 0, :], atol=1e-9)


def test_triangulation_is_exact_on_consistent_pairs():
    rig = _rig()
    x = _points()
    pl, pr = rig.project(x)
    xt, res = triangulate(rig, pl, pr)
    np.testing.assert_allclose(xt, x, atol=1e-9)
    assert res.max() < 1e-9
    # the DLT alone is exact too (no noise), the refinement matters with noise
    xl, _ = triangulate(rig, pl, pr, refine=False)
    np.testing.assert_allclose(xl, x, atol=1e-7)


def test_triangulation_jacobian_matches_finite_differences():
    rig = _rig()
    x = _points(5)
    pl, pr = rig.project(x)
    g = triangulation_jacobian(rig, x)
    obs = np.concatenate([pl, pr], axis=1)
    h = 1e-4
    for k in range(4):
        d = np.zeros_like(obs)
        d[:, k] = h
        xp, _ = triangulate(rig, (obs + d)[:, :2], (obs + d)[:, 2:])
        xm, _ = triangulate(rig, (obs - d)[:, :2], (obs - d)[:, 2:])
        np.testing.assert_allclose((xp - xm) / (2 * h), g[:, :, k], rtol=1e-5, atol=1e-9)


def test_propagation_matches_monte_carlo():
    rig = _rig(20.0)
    x = _points(3, seed=4)
    pl, pr = rig.project(x)
    rng = np.random.default_rng(7)
    cl = np.array([[0.02**2, 0.5 * 0.02 * 0.01], [0.5 * 0.02 * 0.01, 0.01**2]])
    cr = np.diag([0.03**2, 0.015**2])
    cov = propagate(
        triangulation_jacobian(rig, x),
        np.broadcast_to(cl, (3, 2, 2)),
        np.broadcast_to(cr, (3, 2, 2)),
    )
    m = 4000
    nl = rng.multivariate_normal([0, 0], cl, (m, 3))
    nr = rng.multivariate_normal([0, 0], cr, (m, 3))
    xs, _ = triangulate(rig, (pl + nl).reshape(-1, 2), (pr + nr).reshape(-1, 2))
    xs = xs.reshape(m, 3, 3)
    for i in range(3):
        mc = np.cov(xs[:, i].T)
        np.testing.assert_allclose(np.sqrt(np.diag(mc)), np.sqrt(np.diag(cov[i])), rtol=0.06)


@pytest.mark.parametrize("angle", [15.0, 30.0, 45.0])
def test_out_of_plane_ratio_formula(angle):
    # a symmetric rig with ideal cameras, the point where the axes cross
    cam = CameraModel(2000.0, 2000.0, 127.5, 127.5, image_shape=(256, 256))
    rig = symmetric_rig(stereo_angle=angle, distance=400.0, camera=cam)
    p = rig.converge_point()[None]
    cov = propagate(triangulation_jacobian(rig, p), np.eye(2)[None], np.eye(2)[None])[0]
    # along the bisector of the two viewing directions (towards the cameras) and across it
    b = math.radians(angle / 2)
    axis_n = np.array([math.sin(b), 0.0, -math.cos(b)])
    axis_x = np.array([math.cos(b), 0.0, math.sin(b)])
    ratio = math.sqrt(axis_n @ cov @ axis_n / (axis_x @ cov @ axis_x))
    assert ratio == pytest.approx(ratio_out_of_plane(angle), rel=1e-6)


@pytest.mark.parametrize("kind", ["plane", "cylinder"])
def test_compiled_ray_cast_matches_numpy(kind):
    from scipy.ndimage import map_coordinates, spline_filter

    from dicblur.stereo.synthetic import accumulate_rays

    rig = _rig()
    tgt = SpeckleTarget.speckled(kind=kind, rig=rig, size=20.0, texel=0.1, radius=30.0, seed=3)
    rng = np.random.default_rng(2)
    rc = rng.uniform(20, 200, (300, 2))
    dirs = rig.left.rays(rc)
    origins = np.zeros_like(dirs) - np.array([0.1, -0.2, 0.3])
    coef = spline_filter(tgt.texture, order=3, mode="grid-wrap")
    acc = np.zeros(len(dirs))
    es, et, n = tgt.frame()
    frame = np.stack([np.asarray(tgt.origin), es, et, n])
    accumulate_rays(coef, origins, dirs, frame, tgt.radius, tgt.texel, acc)
    _, st = tgt.intersect(origins, dirs)
    ref = map_coordinates(
        coef,
        [st[:, 1] / tgt.texel, st[:, 0] / tgt.texel],
        order=3,
        mode="grid-wrap",
        prefilter=False,
    )
    np.testing.assert_allclose(acc, ref, atol=1e-9)
    # the texture coordinates map back to the hit points
    lam, st = tgt.intersect(np.zeros_like(dirs), dirs)
    np.testing.assert_allclose(tgt.point(st), lam[:, None] * dirs, atol=1e-9)


def _run(args, capsys):
    code = main(args)
    err = capsys.readouterr().err.strip()
    return code, err


@pytest.mark.parametrize(
    ("command", "needle"),
    [
        ("stereo calibrate a.png --board 9by6 -o r.json", "--board="),
        ("stereo calibrate a.png --board 2x6 -o r.json", "--board="),
        ("stereo calibrate a.png --square -5mm -o r.json", "--square="),
        ("stereo calibrate a.png -o r.txt", "--out="),
        ("stereo calibrate nosuch_left_1.png -o r.json", "nosuch_left_1.png"),
        ("stereo track L R --rig none.json --noise 2 -o o", "none.json"),
        ("stereo track L R --rig r.json -o o", "--static"),
        ("stereo track L R --rig r.json --noise 2 --shape x -o o", "--shape="),
        ("stereo track L R --rig r.json --noise 2 --depth -1mm -o o", "--depth="),
    ],
)
def test_cli_bad_inputs_exit_2_with_one_line(tmp_path, monkeypatch, capsys, command, needle):
    monkeypatch.chdir(tmp_path)
    code, err = _run(command.split(), capsys)
    assert code == 2
    assert len(err.splitlines()) == 1 and err.startswith("error: ")
    assert needle in err


def test_cli_names_the_image_without_a_board(tmp_path, capsys):
    from dicblur.io import save_image

    flat = np.random.default_rng(0).uniform(0, 255, (120, 160))
    for i in range(3):
        save_image(tmp_path / f"left_{i}.png", flat)
        save_image(tmp_path / f"right_{i}.png", flat)
    files = sorted(str(p) for p in tmp_path.glob("*.png"))
    code, err = _run(["stereo", "calibrate", *files, "-o", str(tmp_path / "r.json")], capsys)
    assert code == 2 and len(err.splitlines()) == 1
    assert "left_0.png" in err and "checkerboard" in err


def test_relative_shift_is_against_the_blurred_reference():
    from dicblur.stereo.uncertainty import relative_shift

    rng = np.random.default_rng(3)
    xi = rng.normal(size=(5, 7, 4))
    xi[2, 3] = np.nan  # a point whose reference shift is unknown
    out = relative_shift(xi, 2)
    ok = np.ones(7, bool)
    ok[3] = False
    # the reference frame has no mismatch against itself; the others move by its shift
    np.testing.assert_array_equal(out[2, ok], 0.0)
    np.testing.assert_allclose(out[:, ok], xi[:, ok] - xi[2, ok][None])
    # unknown reference shift: the shift against the sharp subset is kept
    np.testing.assert_array_equal(out[[0, 1, 3, 4], 3], xi[[0, 1, 3, 4], 3])
