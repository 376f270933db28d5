"""Campaign engine: spec validation, task seeds, store, serial vs Dask, resume after SIGKILL.

These tests drive the engine with ``helpers.campaign.shift_task``, a cheap real task
(Fourier shift + noise + linearised subset shift estimate), so that they exercise the
engine alone; ``test_campaign_simulate.py`` runs the real blur + DIC task.
"""

from __future__ import annotations

import copy
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import dicblur
from dicblur.campaign import (
    VARIABLES,
    CampaignStore,
    campaign_status,
    directional_sssig,
    export_csv,
    iter_batches,
    load_spec,
    open_results,
    parse_spec,
    run_campaign,
    task_seed,
)
from dicblur.errors import ConfigError, StoreError
from helpers import campaign as campaign_helpers
from helpers.campaign import shift_task, small_spec_dict

HERE = Path(__file__).resolve().parent

COMPARED = [v for v in VARIABLES if v != "time_s"]  # time_s is a wall-clock measurement


def assert_same_results(a, b):
    for name in [*COMPARED, "done"]:
        x, y = a[name].values, b[name].values
        assert np.array_equal(x, y, equal_nan=True), name


# -- spec ----------------------------------------------------------------------------------


def test_spec_defaults_and_dims():
    spec = parse_spec(small_spec_dict())
    assert spec.blur == (0.0, 0.5, 1.0, 1.5, 2.0)
    assert spec.dims == {"pattern": 2, "angle": 1, "subset": 1, "noise": 2, "blur": 5, "rep": 2}
    assert spec.n_tasks == 40
    batches = list(iter_batches(spec))
    # blur_chunk 2 over 5 values: 3 batches per (pattern, noise, rep)
    assert len(batches) == 2 * 2 * 2 * 3
    assert sum(len(b.blur) for b in batches) == spec.n_tasks
    covered = np.zeros(tuple(spec.dims.values()), dtype=int)
    for b in batches:
        covered[b.region] += 1
    assert (covered == 1).all()


def test_spec_hash_ignores_spelling_not_content(tmp_path):
    a = parse_spec(small_spec_dict())
    b = parse_spec(small_spec_dict(blur__lengths=[0, 0.5, 1.0, 1.5, 2]))
    assert a.content_hash() == b.content_hash()
    c = parse_spec(small_spec_dict(blur__lengths=[0, 0.5, 1.0, 1.5, 2.5]))
    assert a.content_hash() != c.content_hash()
    toml = tmp_path / "s.toml"
    toml.write_text(
        textwrap.dedent("""
        # a comment
        [campaign]
        seed = 7
        name = "t"
        repetitions = 2
        [[pattern]]
        name = "a"
        generator = "speckle"
        shape = [64, 64]
        speckle_size = 4.0
        seed = 1
        [[pattern]]
        name = "b"
        generator = "paper4"
        shape = [64, 64]
        seed = 2
        [blur]
        lengths = {start = 0.0, stop = 2.0, step = 0.5}
        [noise]
        model = "per-exposure"
        levels = [1, 2]
        [dic]
        subsets = [15]
        step = 8
        [run]
        blur_chunk = 2
    """)
    )
    assert load_spec(toml).content_hash() == a.content_hash()


def test_range_grid_is_exact():
    spec = parse_spec(small_spec_dict(blur__lengths={"start": 0.1, "stop": 10.0, "step": 0.1}))
    assert len(spec.blur) == 100
    assert spec.blur[2] == 0.3 and spec.blur[-1] == 10.0


@pytest.mark.parametrize(
    ("change", "key"),
    [
        ({"campaign__seed": -1}, "campaign.seed"),
        ({"campaign__repetitions": 0}, "campaign.repetitions"),
        ({"campaign__colour": 1}, "campaign.colour"),
        ({"blur__lengths": [1.0, -1.0]}, "blur.lengths"),
        ({"blur__lengths": [1.0, 1.0]}, "blur.lengths"),
        ({"blur__lengths": {"start": 0, "stop": 1}}, "blur.lengths"),
        ({"blur__method": "magic"}, "blur.method"),
        ({"blur__boundary": "wrap"}, "blur.boundary"),
        ({"blur__trajectory": "zigzag"}, "blur.trajectory"),
        ({"noise__model": "speckle"}, "noise.model"),
        ({"noise__levels": [-2.0]}, "noise.levels"),
        ({"noise__model": "poisson-gaussian"}, "noise.full_well"),
        ({"noise__full_well": 1000.0}, "noise.full_well"),
        ({"dic__subsets": [20]}, "dic.subsets"),
        ({"dic__shape": "quadratic"}, "dic.shape"),
        ({"dic__tolerance": 0.0}, "dic.tolerance"),
        ({"dic__step": 0}, "dic.step"),
        ({"run__blur_chunk": 0}, "run.blur_chunk"),
    ],
)
def test_spec_errors_name_the_key(change, key):
    with pytest.raises(ConfigError) as info:
        parse_spec(small_spec_dict(**change))
    assert str(info.value).startswith(key), str(info.value)


def test_spec_pattern_errors(tmp_path):
    d = small_spec_dict()
    d["pattern"][0]["speckel_size"] = 3
    with pytest.raises(ConfigError, match=r"pattern\[0\]\.speckel_size"):
        parse_spec(d)
    d = small_spec_dict()
    d["pattern"][1]["path"] = "x.tif"
    with pytest.raises(ConfigError, match="exactly one of 'generator'"):
        parse_spec(d)
    d = small_spec_dict()
    d["pattern"][1]["name"] = "a"
    with pytest.raises(ConfigError, match=r"pattern\.name"):
        parse_spec(d)
    d = small_spec_dict()
    d["blur"]["method"] = "rendered"  # pattern b is paper4: cannot be rendered
    with pytest.raises(ConfigError, match=r"blur\.method"):
        parse_spec(d)
    with pytest.raises(ConfigError, match="no such file"):
        load_spec(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[campaign\nseed = 1")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_spec(bad)
    with pytest.raises(ConfigError, match=r"campaign\.seed"):
        parse_spec({"pattern": small_spec_dict()["pattern"], "blur": {"lengths": [1.0]}})


# -- seeds -----------------------------------------------------------------------------------


def test_task_seed_depends_on_values_not_order():
    a = task_seed(3, "current", pattern="p", blur=0.5, rep=1)
    b = task_seed(3, "current", rep=1, blur=0.5, pattern="p")
    assert a.generate_state(4).tolist() == b.generate_state(4).tolist()
    others = [
        task_seed(4, "current", pattern="p", blur=0.5, rep=1),
        task_seed(3, "reference", pattern="p", blur=0.5, rep=1),
        task_seed(3, "current", pattern="p", blur=0.6, rep=1),
        task_seed(3, "current", pattern="q", blur=0.5, rep=1),
    ]
    states = {tuple(s.generate_state(4).tolist()) for s in [a, *others]}
    assert len(states) == 5


@pytest.mark.slow
def test_batch_size_does_not_change_results(tmp_path):
    # Seeds are keyed by coordinate values: any chunking of the blur axis gives the same
    # bytes (only the store layout differs).
    s2 = parse_spec(small_spec_dict())
    s5 = parse_spec(small_spec_dict(run__blur_chunk=5))
    run_campaign(s2, tmp_path / "a.zarr", serial=True, task=shift_task)
    run_campaign(s5, tmp_path / "b.zarr", serial=True, task=shift_task)
    assert_same_results(open_results(tmp_path / "a.zarr"), open_results(tmp_path / "b.zarr"))


# -- metrics helper ------------------------------------------------------------------------


def test_directional_sssig_against_metrics_and_closed_form():
    img = dicblur.speckle_pattern((48, 48), speckle_size=4, seed=3)
    pts = dicblur.subset_centres(img.shape, subset=11, step=9)
    sx = directional_sssig(img, pts, subset=11, angle=0.0)
    sy = directional_sssig(img, pts, subset=11, angle=90.0)
    np.testing.assert_allclose(sx, dicblur.sssig(img, subset=11, points=pts), rtol=1e-12)
    np.testing.assert_allclose(
        sy, dicblur.sssig(img, subset=11, points=pts, direction="y"), rtol=1e-12
    )
    # 45 degrees: explicit sum of (fx + fy)^2 / 2 over each subset
    gy, gx = dicblur.image_gradients(img)
    g = (gx + gy) / np.sqrt(2.0)
    want = [np.sum(g[r - 5 : r + 6, c - 5 : c + 6] ** 2) for r, c in pts]
    np.testing.assert_allclose(directional_sssig(img, pts, subset=11, angle=45.0), want, rtol=1e-10)


# -- runs, resume, storage ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def serial_run(tmp_path_factory):
    path = tmp_path_factory.mktemp("serial") / "r.zarr"
    summary = run_campaign(parse_spec(small_spec_dict()), path, serial=True, task=shift_task)
    return path, summary


def test_serial_run_stores_every_task(serial_run):
    path, summary = serial_run
    assert summary.complete and summary.n_run == 40 and summary.n_skipped == 0
    ds = open_results(path)
    assert dict(ds.sizes) == {
        "pattern": 2,
        "angle": 1,
        "subset": 1,
        "noise": 2,
        "blur": 5,
        "rep": 2,
    }
    assert (ds["done"] == 1).all()
    for name in VARIABLES:
        assert np.isfinite(ds[name].values).all(), name
    # spot check one task against a direct call of the task function
    spec = parse_spec(small_spec_dict())
    b = next(
        x
        for x in iter_batches(spec)
        if x.pattern == "b" and x.noise == 2.0 and x.rep == 1 and 1.5 in x.blur
    )
    direct = shift_task(dicblur.paper_pattern4((64, 64), seed=2), b, spec)
    j = b.blur.index(1.5)
    got = ds.sel(pattern="b", noise=2.0, rep=1, blur=1.5).isel(angle=0, subset=0)
    assert float(got["u_e"]) == direct["u_e"][j]
    assert float(got["sssig"]) == direct["sssig"][j]
    assert json.loads(ds.attrs["spec"]) == spec.to_dict()
    assert ds.attrs["spec_hash"] == spec.content_hash()
    assert set(json.loads(ds.attrs["input_hashes"])) == {"a", "b"}
    assert "numpy" in json.loads(ds.attrs["versions"])


def test_rerun_skips_finished_tasks(serial_run, tmp_path):
    path, _ = serial_run
    copy_path = tmp_path / "copy.zarr"
    shutil.copytree(path, copy_path)
    again = run_campaign(parse_spec(small_spec_dict()), copy_path, serial=True, task=shift_task)
    assert again.n_run == 0 and again.n_skipped == 40 and again.complete
    st = campaign_status(copy_path)
    assert st.complete and st.n_done == 40 and st.done_by_pattern == {"a": 20, "b": 20}


@pytest.mark.slow
@pytest.mark.numba_cache
def test_local_cluster_equals_serial(serial_run, tmp_path):
    import cloudpickle

    cloudpickle.register_pickle_by_value(campaign_helpers)  # workers cannot import tests/
    path, _ = serial_run
    summary = run_campaign(
        parse_spec(small_spec_dict()), tmp_path / "dask.zarr", workers=2, task=shift_task
    )
    assert summary.workers == 2 and summary.scheduler == "local" and summary.complete
    assert_same_results(open_results(path), open_results(tmp_path / "dask.zarr"))


@pytest.mark.slow
@pytest.mark.numba_cache
def test_interrupt_on_local_cluster_keeps_finished_batches(serial_run, tmp_path):
    # Ctrl-C while the cluster runs: pending tasks cancelled, cluster closed, the finished
    # batches stored; the rerun completes to the same values.
    import cloudpickle

    cloudpickle.register_pickle_by_value(campaign_helpers)
    path, _ = serial_run
    spec = parse_spec(small_spec_dict())

    def stop(done, total):
        if done >= 2:
            raise KeyboardInterrupt

    out = tmp_path / "int_dask.zarr"
    first = run_campaign(spec, out, workers=2, task=shift_task, progress=stop)
    assert first.interrupted and 2 <= first.n_run < 40
    assert campaign_status(out).n_done == first.n_run
    second = run_campaign(spec, out, serial=True, task=shift_task)
    assert second.complete and second.n_skipped == first.n_run
    assert_same_results(open_results(path), open_results(out))


@pytest.mark.slow
def test_interrupt_keeps_finished_batches_and_resume_completes(serial_run, tmp_path):
    path, _ = serial_run
    spec = parse_spec(small_spec_dict())
    calls = []

    def stop_after_some(done, total):
        calls.append(done)
        if done >= 10:
            raise KeyboardInterrupt

    out = tmp_path / "int.zarr"
    first = run_campaign(spec, out, serial=True, task=shift_task, progress=stop_after_some)
    assert first.interrupted and not first.complete and first.n_run == 10
    st = campaign_status(out)
    assert st.n_done == 10
    partial = open_results(out)
    assert int(np.isfinite(partial["u_e"].values).sum()) == 10  # nothing half-visible
    second = run_campaign(spec, out, serial=True, task=shift_task)
    assert second.n_skipped == 10 and second.n_run == 30 and second.complete
    assert_same_results(open_results(path), open_results(out))


RUNNER = """
from helpers.campaign import kill_spec, shift_task
from dicblur.campaign import run_campaign
run_campaign(kill_spec(), {out!r}, serial=True, task=shift_task)
"""


@pytest.mark.slow
@pytest.mark.numba_cache
def test_sigkill_at_random_point_then_resume_is_bit_identical(tmp_path):
    spec = campaign_helpers.kill_spec()
    out = tmp_path / "killed.zarr"
    script = tmp_path / "runner.py"
    script.write_text(RUNNER.format(out=str(out)))
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join(  # tests/ for the helpers package
            [str(HERE), *filter(None, [os.environ.get("PYTHONPATH")])]
        ),
    )
    proc = subprocess.Popen([sys.executable, str(script)], stderr=subprocess.PIPE, env=env)
    try:
        done_dir = out / "done" / "c"
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:
            if done_dir.exists() and any(p.is_file() for p in done_dir.rglob("*")):
                break
            time.sleep(0.005)
        assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
        time.sleep(random.uniform(0.0, 0.5))  # a random point of the run
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if proc.stderr:
            proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    before = campaign_status(out)
    assert 0 < before.n_done < spec.n_tasks, "the kill did not land mid-run"
    resumed = run_campaign(spec, out, serial=True, task=shift_task)
    assert resumed.complete and resumed.n_skipped == before.n_done
    reference = tmp_path / "clean.zarr"
    run_campaign(spec, reference, serial=True, task=shift_task)
    assert_same_results(open_results(reference), open_results(out))


# -- store errors --------------------------------------------------------------------------


def test_changed_spec_is_refused(serial_run, tmp_path):
    path, _ = serial_run
    copy_path = tmp_path / "c.zarr"
    shutil.copytree(path, copy_path)
    other = parse_spec(small_spec_dict(noise__levels=[1.0, 3.0]))
    with pytest.raises(StoreError, match=r"different campaign.*noise\.levels"):
        run_campaign(other, copy_path, serial=True, task=shift_task)


def test_changed_input_image_is_refused(tmp_path):
    img_path = tmp_path / "pat.png"
    dicblur.save_image(img_path, dicblur.speckle_pattern((64, 64), seed=5))
    d = small_spec_dict()
    d["pattern"] = [{"name": "file", "path": str(img_path), "crop": [0, 0, 48, 48]}]
    spec = parse_spec(d)
    out = tmp_path / "f.zarr"
    run_campaign(spec, out, serial=True, task=shift_task)
    st = campaign_status(out)
    assert st.input_hashes["file"] == "file-sha256:" + dicblur.file_sha256(img_path)
    dicblur.save_image(img_path, dicblur.speckle_pattern((64, 64), seed=6))
    with pytest.raises(StoreError, match="input image of pattern 'file' changed"):
        run_campaign(spec, out, serial=True, task=shift_task)


def test_crop_outside_image_is_config_error(tmp_path):
    img_path = tmp_path / "pat.png"
    dicblur.save_image(img_path, dicblur.speckle_pattern((64, 64), seed=5))
    d = small_spec_dict()
    d["pattern"] = [{"name": "file", "path": "pat.png", "crop": [20, 0, 48, 48]}]
    spec = parse_spec(d, base_dir=tmp_path)
    with pytest.raises(ConfigError, match="crop"):
        run_campaign(spec, tmp_path / "x.zarr", serial=True, task=shift_task)


def test_damaged_stores_give_clear_errors(serial_run, tmp_path):
    path, _ = serial_run
    with pytest.raises(StoreError, match="no such store"):
        campaign_status(tmp_path / "nothing.zarr")
    (tmp_path / "plain").mkdir()
    (tmp_path / "plain" / "readme.txt").write_text("not a store")
    with pytest.raises(StoreError, match="results="):
        campaign_status(tmp_path / "plain")
    missing = tmp_path / "missing.zarr"
    shutil.copytree(path, missing)
    shutil.rmtree(missing / "sssig")
    with pytest.raises(StoreError, match="'sssig' is missing"):
        run_campaign(parse_spec(small_spec_dict()), missing, serial=True, task=shift_task)
    torn = tmp_path / "torn.zarr"
    shutil.copytree(path, torn)
    chunk = next(p for p in (torn / "done" / "c").rglob("*") if p.is_file())
    chunk.write_bytes(b"\x01")  # truncated chunk: its batch is damaged, not an error
    st = campaign_status(torn)
    assert st.n_damaged in (1, 2) and st.n_done == 40 - st.n_damaged and not st.complete
    attrs = tmp_path / "attrs.zarr"
    shutil.copytree(path, attrs)
    meta = json.loads((attrs / "zarr.json").read_text())
    meta["attributes"]["spec"] = "{not json"
    (attrs / "zarr.json").write_text(json.dumps(meta))
    with pytest.raises(StoreError, match="corrupt spec attribute"):
        open_results(attrs)
    with pytest.raises(StoreError, match="already exists"):
        CampaignStore.create(path, parse_spec(small_spec_dict()), {})


def test_task_result_is_checked_before_writing(tmp_path):
    spec = parse_spec(small_spec_dict())

    def incomplete(image, batch, spec_):
        out = shift_task(image, batch, spec_)
        del out["bias"]
        return out

    out = tmp_path / "i.zarr"
    with pytest.raises(StoreError, match="'bias' missing"):
        run_campaign(spec, out, serial=True, task=incomplete)
    assert campaign_status(out).n_done == 0


def test_export_csv_one_row_per_finished_task(serial_run, tmp_path):
    import csv

    path, _ = serial_run
    csv_path = tmp_path / "r.csv"
    assert export_csv(path, csv_path) == 40
    with open(csv_path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 40
    assert list(rows[0])[:6] == ["pattern", "angle", "subset", "noise", "blur", "rep"]
    ds = open_results(path)
    r = next(
        x
        for x in rows
        if x["pattern"] == "a" and x["blur"] == "1.0" and x["noise"] == "2.0" and x["rep"] == "0"
    )
    want = ds.sel(pattern="a", blur=1.0, noise=2.0, rep=0).isel(angle=0, subset=0)
    for name in VARIABLES:
        assert float(r[name]) == float(want[name]), name


def test_spec_is_not_mutated_by_parsing():
    d = small_spec_dict()
    before = copy.deepcopy(d)
    parse_spec(d)
    assert d == before
