"""Exposure planning for a 3-D target (dicblur.stereo.plan, ``dicblur stereo plan``).

Synthetic: a 2-D model fitted to the mismatch model's own u_e(W) (as tests/test_planner.py),
symmetric rigs built in the test; the checks are the closed forms of docs/stereo.md and
the plan's defining property (sigma at the planned exposure equals the target, a longer one
misses it).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from dicblur.cli import main
from dicblur.errors import InputError
from dicblur.models import fit_blur_model, mismatch_model, sssig_decay
from dicblur.stereo import CameraModel, save_rig
from dicblur.stereo.plan import (
    parse_vector,
    plan_stereo_exposure,
    stereo_sigma,
    target_frame,
)
from dicblur.stereo.synthetic import symmetric_rig
from dicblur.stereo.uncertainty import ratio_out_of_plane

S0, BETA = 2.4e6, 0.03


@pytest.fixture(scope="module")
def model():
    rng = np.random.default_rng(1)
    w0 = np.arange(0.0, 6.01, 0.5)
    w = np.tile(w0, 2)
    sig = np.repeat([2.0, 8.0], w0.size)
    s = sssig_decay(w, S0, BETA)
    u = mismatch_model(w, s, sig, c=9e-4, a=1.4, floor=9e-4) * np.exp(rng.normal(0.0, 0.02, w.size))
    return fit_blur_model(w, s, u, noise_sigma=sig, subset=31, mean_level=120.0)


def _rig(angle=30.0):
    cam = CameraModel(2000.0, 2000.0, 255.5, 255.5, (0, 0, 0, 0, 0), (512, 512))
    return symmetric_rig(stereo_angle=angle, distance=400.0, camera=cam)


def test_static_sigma_follows_the_closed_form(model):
    for angle in (15.0, 30.0, 45.0):
        rig = _rig(angle)
        s = stereo_sigma(
            rig, model, point=rig.converge_point(), motion=np.zeros((1, 3)), sigma=2.0
        )[0][0]
        beta = math.radians(angle) / 2
        assert s[2] / s[0] == pytest.approx(ratio_out_of_plane(angle), rel=1e-6)
        # sigma_x^2 = (s_L^2 + s_R^2) / (4 cos^2 beta), s the image error in mm at the
        # point: u_e x distance / focal length (the right camera 400 / cos(theta) away)
        u0 = float(model.predict([0.0], 2.0).u_e[0])
        s_l = u0 * 400.0 / 2000.0
        s_r = s_l / math.cos(math.radians(angle))
        want = math.sqrt(s_l**2 + s_r**2) / (2 * math.cos(beta))
        assert s[0] == pytest.approx(want, rel=2e-3)
        # y: two measurements of one coordinate, weighted (equal s: the docs' s^2 / 2)
        assert s[1] == pytest.approx((s_l**-2 + s_r**-2) ** -0.5, rel=2e-3)


def test_target_frame_is_the_bisector_frame():
    rig = _rig(30.0)
    f = target_frame(rig, rig.converge_point())
    np.testing.assert_allclose(f @ f.T, np.eye(3), atol=1e-12)
    # the right camera at +x turned by 30 deg about y: z along the bisector (away from
    # the rig), x towards the right camera, y down as in the cameras
    a = math.radians(15.0)
    np.testing.assert_allclose(f[2], [-math.sin(a), 0.0, math.cos(a)], atol=1e-12)
    np.testing.assert_allclose(f[0], [math.cos(a), 0.0, math.sin(a)], atol=1e-12)
    np.testing.assert_allclose(f[1], [0.0, 1.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("velocity", ["100,0,0mm/s", "0,0,100mm/s", "0,0.05,0.05m/s"])
def test_planned_exposure_meets_the_target_and_no_more(model, velocity):
    rig = _rig(30.0)
    plan = plan_stereo_exposure(rig, model, velocity=velocity, target="5um", sigma=2.0)
    assert 0 < plan.exposure < math.inf
    assert max(plan.sigma) == pytest.approx(5e-3, rel=1e-3)
    f = target_frame(rig, np.array(plan.point))
    v = f.T @ parse_vector(velocity, "velocity", "velocity")
    longer = stereo_sigma(
        rig, model, point=np.array(plan.point), motion=1.01 * plan.exposure * v[None], sigma=2.0
    )[0][0]
    assert max(longer) > 5e-3
    # the z component alone allows at least as long an exposure as the worst one
    pz = plan_stereo_exposure(rig, model, velocity=velocity, target="5um", sigma=2.0,
                              component="z", angles=())  # fmt: skip
    assert pz.exposure >= plan.exposure * (1 - 1e-9)
    assert math.isnan(pz.best_angle)


def test_angle_advice_follows_the_blur_geometry(model):
    # in-plane motion along the baseline: a wider angle lowers sigma_z at little extra
    # blur; out of plane the blur grows as sin(beta) in both cameras: narrower is better
    rig = _rig(30.0)
    x = plan_stereo_exposure(rig, model, velocity="100,0,0mm/s", target="5um", sigma=2.0)
    z = plan_stereo_exposure(rig, model, velocity="0,0,100mm/s", target="5um", sigma=2.0)
    ex = [o.exposure for o in x.angles]
    ez = [o.exposure for o in z.angles]
    assert ex == sorted(ex) and x.best_angle == 60.0
    assert z.best_angle < 30.0
    # the 30 deg entry is the rig itself
    o30 = next(o for o in z.angles if o.stereo_angle == 30.0)
    assert o30.exposure == pytest.approx(z.exposure, rel=1e-9)
    # out of plane each camera sees v_n T sin(beta) f / distance: the right camera is
    # 400 / cos(theta) away
    assert z.blur_left / z.blur_right == pytest.approx(1 / math.cos(math.radians(30)), rel=1e-3)
    assert ez[0] > ez[-1]


def test_unreachable_target_and_bad_input(model):
    rig = _rig(30.0)
    plan = plan_stereo_exposure(rig, model, velocity="0,0,100mm/s", target="0.1um", sigma=2.0)
    assert plan.exposure == 0.0 and "still target" in plan.notes[0]
    np.testing.assert_allclose(
        parse_vector("0,0,0.1m/s", "velocity", "velocity"), [0.0, 0.0, 100.0]
    )
    with pytest.raises(InputError, match="velocity="):
        plan_stereo_exposure(rig, model, velocity="1,2mm/s", target="5um")
    with pytest.raises(InputError, match="velocity="):
        plan_stereo_exposure(rig, model, velocity="0,0,0mm/s", target="5um")
    with pytest.raises(InputError, match="target="):
        plan_stereo_exposure(rig, model, velocity="0,0,1mm/s", target="-5um")


def test_cli_plan(model, tmp_path, capsys):
    mp, rp = tmp_path / "model.json", tmp_path / "rig.json"
    model.to_json(str(mp))
    save_rig(_rig(30.0), rp)
    args = ["stereo", "plan", str(mp), "--rig", str(rp), "--velocity", "0,0,100mm/s"]
    code = main([*args, "--target", "5um", "--noise", "2", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    api = plan_stereo_exposure(_rig(30.0), model, velocity="0,0,100mm/s", target="5um", sigma=2.0)
    assert out["exposure"] == pytest.approx(api.exposure, rel=1e-12)
    code = main([*args[:-1], "0,0mm/s", "--target", "5um"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.count("\n") == 0 and "--velocity=" in err
    code = main([*args, "--target", "5um", "--component", "w"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "--component=" in err
