"""Strains in ``dicblur track`` and on real images (issue 28)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import dicblur
from dicblur.dic import Correlator
from dicblur.strain import StrainStatus
from dicblur.track.store import write_track_csv

_HERE = Path(__file__).resolve()
REAL = next(
    (
        p
        for p in (
            _HERE.parents[1].parent / "shared" / "data" / "real",
            _HERE.parents[2].parent / "shared" / "data" / "real",
        )
        if p.is_dir()
    ),
    _HERE.parents[1].parent / "shared" / "data" / "real",
)


@pytest.mark.slow
def test_track_writes_strains_beside_u_v(tmp_path):
    from dicblur.report.track import write_track_report
    from dicblur.track.synthetic import VibratingTarget

    pat = dicblur.speckle_pattern(160, speckle_size=4.0, softness=1.0, seed=2)
    tgt = VibratingTarget(pat, fps=2000.0, exposure=0.4e-3, amplitude=4.0, static=4)
    ds = dicblur.track(tgt.recording(16), static="0:4", advice=False, strain=3)
    for name in ("exx", "eyy", "exy", "sigma_exx", "sigma_exx_noise", "sigma_exx_blur"):
        assert ds[name].shape == ds["u"].shape, name
    assert ds.attrs["strain_vsg"] == 2 * 10 + 21
    ok = ds["strain_status"].values == StrainStatus.OK
    assert ok.any()
    # a rigid motion: the strains are errors, within a few predicted sigmas
    z = ds["exx"].values[ok] / ds["sigma_exx"].values[ok]
    assert 0.5 < float(np.std(z)) < 1.5
    # the moving frames have a blur part, the static ones none
    moving = ds["W"].values > 1.0
    assert np.nanmax(ds["sigma_exx_blur"].values[moving & ok]) > 0
    # never a value without its status
    assert np.all(np.isfinite(ds["exx"].values[ok]))
    assert np.all(np.isnan(ds["exx"].values[ds["strain_status"].values >= 2]))
    csv_path = write_track_csv(ds, tmp_path / "track.csv")
    header = csv_path.read_text().splitlines()[0].split(",")
    assert "sigma_exx" in header and header[-1] == "strain_status"
    report = write_track_report(ds, tmp_path)
    assert "exx of the points with a full plane-fit window" in report.read_text()


@pytest.mark.skipif(
    not (REAL / "dicchallenge1_sample3").exists(),
    reason="DIC Challenge images not present (shared/data/real beside the repo)",
)
def test_real_sample3_rigid_shift_strain_is_zero_within_sigma():
    """Sample 3 at zero shift with independent noise (about 1.1 GL per image): the
    strains are pure error, so they must scatter as their predicted sigma."""
    folder = REAL / "dicchallenge1_sample3"
    ref = dicblur.load_image(folder / "Sample3_Reference.tif")
    cur = dicblur.load_image(folder / "Sample3-000_X0.00_Y0.00_N2_C0_R0.tif")
    corr = Correlator(ref, subset=21, step=10, shape="affine", noise_sigma=1.1)
    s = dicblur.strain(corr.correlate(cur), window=5)
    ok = s.status == StrainStatus.OK
    assert ok.sum() > 1000
    for name in ("exx", "eyy", "exy"):
        z = getattr(s, name)[ok] / getattr(s, f"sigma_{name}")[ok]
        assert abs(float(np.mean(z))) < 0.3, name
        assert 0.7 < float(np.std(z)) < 1.3, (name, float(np.std(z)))
