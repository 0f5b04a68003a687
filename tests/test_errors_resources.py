"""Issue 21, classes 5 and 6: data too large for the pointwise groups, and the faults and odd
arguments that gave tracebacks (impossible rows, deep TOML, full or read-only disks, bad
numbers): each a one-line error with exit status 2 and the previous result untouched."""

import importlib
import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import skinfit
from skinfit.apps.cli import main
from skinfit.errors import InputError
from skinfit.inference.optimize import MAPError
from skinfit.posterior import Posterior

run_module = importlib.import_module("skinfit.inference.run")
fitting_module = importlib.import_module("skinfit.results.fitting")
store_module = importlib.import_module("skinfit.results.store")
ROOT = Path(skinfit.__file__).resolve().parents[1]
DATA_DIR = ROOT / "datasets" / "electroadhesion_synthetic"
MODEL = "electroadhesion_coulomb"  # the cheapest model on the shipped electroadhesion data


def _quiet_fit(*args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return skinfit.fit(*args, **kwargs)


def _no_fit(*args, **kwargs):
    raise AssertionError("a fit started on input it should have refused")


def _dataset_with(tmp_path, rows, column, force):
    """The shipped electroadhesion data with ``column`` of ``rows`` (1-based) set to ``force`` (mN)."""
    d = tmp_path / "ds"
    shutil.copytree(DATA_DIR, d)
    frame = pd.read_csv(d / "data.csv")
    frame.loc[np.array(rows) - 1, column] = force
    frame.to_csv(d / "data.csv", index=False)
    return d


# ---- class 5: memory ---------------------------------------------------------------------------
def _large_rows(n_copies):
    """The shipped electroadhesion design repeated ``n_copies`` times (216 * n_copies rows)."""
    ds = skinfit.load_dataset("electroadhesion_synthetic")
    frame = pd.concat([ds.frame] * n_copies, ignore_index=True)
    return skinfit.io.data.Dataset(f"{ds.id}x{n_copies}", ds.title, frame, ds.columns, ds.groups, ds.provenance,
                                ds.model, ds.path, ds.sha256 + f"x{n_copies}")


def test_class5_pointwise_groups_thinned_to_the_memory_budget(monkeypatch, tmp_path):
    """4320 rows; the available memory patched so that all draws need 6.5x the budget: every
    7th draw of each walker is kept, the note is in the text and the file, and LOO, the
    misfit check and a save/load still work on the kept draws."""
    fit = _quiet_fit(MODEL, _large_rows(20), rng=1, complete=False)
    nw, nd = fit.attr("sampler")["nwalkers"], fit.group("posterior").sizes["draw"]
    need = run_module.pointwise_bytes(1, 4320, nw * nd)
    monkeypatch.setattr(run_module, "available_memory", lambda: need / 6.5 / run_module.MEMORY_FRACTION)
    with pytest.warns(UserWarning, match="on every 7th draw of each walker"):
        fit.complete()
    ll = fit.group("log_likelihood")
    assert ll.sizes["chain"] == nw and ll.sizes["draw"] == len(range(0, nd, 7)) and ll.sizes["obs_id"] == 4320
    assert list(ll["draw"].values) == list(range(0, nd, 7))
    assert fit.group("posterior").sizes["draw"] == nd  # the posterior keeps every draw
    assert fit.attr("misfit")["draws"] == min(400, nw * len(range(0, nd, 7)))  # misfit.PPC_DRAWS of the kept
    assert "note: pointwise log-likelihood and predictive draws on every 7th draw" in fit.report_text()
    saved = skinfit.load_fit(fit.save(tmp_path / "fit.nc"))
    assert saved.attr("pointwise_thinned")["every"] == 7
    from skinfit.analysis.compare import loo

    assert np.isfinite(float(loo(saved).elpd))


def test_class5_one_draw_of_every_jth_walker_when_a_draw_per_walker_is_over_budget(monkeypatch):
    fit = _quiet_fit(MODEL, _large_rows(20), rng=1, complete=False)
    nw = fit.attr("sampler")["nwalkers"]
    per_draw = run_module.pointwise_bytes(1, 4320, 1)
    monkeypatch.setattr(run_module, "available_memory", lambda: per_draw * 5.5 / run_module.MEMORY_FRACTION)
    with pytest.warns(UserWarning, match=rf"one draw of every {-(-nw // 5)}th walker"):
        fit.complete()
    ll = fit.group("log_likelihood")
    assert list(ll["chain"].values) == list(range(0, nw, -(-nw // 5))) and ll.sizes["draw"] == 1
    assert fit.attr("misfit")["underpowered"]  # 5 draws cannot reach p < 0.05 / m
    assert "fit to the data: NOT CHECKED: 5 pointwise draws (memory)" in fit.report_text()


def test_class5_refused_before_the_map_when_one_draw_is_over_budget(monkeypatch):
    monkeypatch.setattr(run_module, "available_memory", lambda: 100_000.0)
    monkeypatch.setattr(run_module, "find_map", _no_fit)
    with pytest.raises(InputError, match=r"one posterior draw's .* would need 0\.1 MiB \(4320 rows x 1 observable"):
        skinfit.fit(MODEL, _large_rows(20), rng=1)


# ---- class 6: impossible rows, deep TOML ------------------------------------------------------
# A zero normal force makes the JKR area impossible. An absurd friction force (1e9 N) is out of
# every parameter's reach: |mu| <= 2 with newton-scale normal and electrostatic forces and a noise
# scale <= 1 N, so the outcome cannot depend on where the seed's starts land. (An absurd *normal*
# force is not such a case: mu -> 0 matches it, a needle-thin mode a start may or may not find.)
@pytest.mark.parametrize("column, force, why", [("normal_force", 0.0, "every draw is impossible at"),
                                                ("tangential_force", 1e12, "no draw comes within 1000 noise scales of")])
def test_class6_zero_or_absurd_forces_name_the_rows(tmp_path, capsys, column, force, why):
    d = _dataset_with(tmp_path, [3, 7], column, force)
    model = "electroadhesion" if force == 0.0 else MODEL
    with pytest.raises(MAPError, match=rf"{why} data row\(s\) 3, 7 \(normal_force = "):
        _quiet_fit(model, str(d), rng=1)
    assert main(["fit", model, str(d), "--out", str(tmp_path / "run"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "data row(s) 3, 7" in err and not (tmp_path / "run" / "fit.nc").exists()


@pytest.mark.parametrize("text", ["x = " + "[" * 5000 + "]" * 5000, "x = " + "{a = " * 3000 + "1" + "}" * 3000,
                                  "[" + "a." * 3000 + "b]\nc = 1"])
def test_class6_deeply_nested_toml_is_an_input_error(tmp_path, text):
    path = tmp_path / "m.toml"
    path.write_text("schema_version = 1\n" + text + "\n")
    with pytest.raises(InputError, match=r"m\.toml: "):
        skinfit.load_model(str(path))


# ---- class 6: full and read-only disks --------------------------------------------------------
@pytest.fixture(scope="module")
def saved_fit(tmp_path_factory):
    out = tmp_path_factory.mktemp("prev")
    fit = _quiet_fit(MODEL, "electroadhesion_synthetic", rng=3)
    return fit, fit.save(out / "fit.nc")


def test_class6_full_disk_before_the_save_keeps_the_previous_file(saved_fit, monkeypatch):
    fit, path = saved_fit
    before = path.read_bytes()
    usage = shutil.disk_usage(path.parent)
    monkeypatch.setattr(store_module.shutil, "disk_usage", lambda p: usage._replace(free=4096))
    with pytest.raises(OSError, match=r"no space to save the fit: .* MiB needed, 0\.0 MiB free"):
        fit.save(path)
    assert path.read_bytes() == before and sorted(p.name for p in path.parent.iterdir()) == ["fit.nc"]


def test_class6_disk_full_during_the_write_keeps_the_previous_file(saved_fit, monkeypatch):
    fit, path = saved_fit
    before = path.read_bytes()
    real = os.fdopen

    class Full:
        def __init__(self, f):
            self.f = f

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

        def write(self, data):
            raise OSError(28, "No space left on device")

    monkeypatch.setattr(store_module.os, "fdopen", lambda fd, mode: Full(real(fd, mode)))
    with pytest.raises(OSError, match=r"cannot write: No space left on device"):
        fit.save(path)
    assert path.read_bytes() == before and sorted(p.name for p in path.parent.iterdir()) == ["fit.nc"]


def _mount_tmpfs(directory, size):
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(directory)], capture_output=True)
    return r.returncode == 0


@pytest.mark.parametrize("filler", [0, 900_000])
def test_class6_full_tmpfs_gives_one_line_and_no_crash(tmp_path, filler):
    """A real 1 MiB tmpfs (root only): the fit's 8 MiB file, or with 0.9 MiB filled the
    checkpoint too, does not fit.  Before: an OSError traceback and rc 139 (HDF5 writing to
    the full disk crashed the interpreter at exit); now one line and exit status 2."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    if not _mount_tmpfs(mnt, "1m"):
        pytest.skip("cannot mount a tmpfs here (needs root)")
    try:
        (mnt / "filler").write_bytes(b"\0" * filler)
        r = subprocess.run([sys.executable, "-m", "skinfit", "fit", MODEL, "electroadhesion_synthetic", "--out",
                            str(mnt / "run"), "--quiet", "--seed", "1"], capture_output=True, text=True, timeout=600)
        assert r.returncode == 2, r.stderr[-2000:]
        last = r.stderr.strip().splitlines()[-1]
        assert last.startswith("skinfit: error: ") and ("No space left on device" in last or "no space" in last)
        assert "Traceback" not in r.stderr
        assert not (mnt / "run" / "fit.nc").exists() and not list((mnt / "run").glob("*.tmp"))
    finally:
        subprocess.run(["umount", str(mnt)], check=False)


def test_class6_read_only_run_directory_gives_one_line(saved_fit, tmp_path, capsys, monkeypatch):
    _, path = saved_fit
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(path, run / "fit.nc")
    before = (run / "fit.nc").read_bytes()

    def read_only(*args, **kwargs):
        raise PermissionError(30, "Read-only file system", str(run / "checkpoint.h5"))

    monkeypatch.setattr(fitting_module, "fit", _no_fit)
    monkeypatch.setattr(importlib.import_module("skinfit.inference.checkpoint").CheckpointLock, "__enter__", read_only)
    assert main(["fit", MODEL, "electroadhesion_synthetic", "--out", str(run), "--quiet", "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Read-only file system (errno 30); files written before are unchanged" in err
    assert (run / "fit.nc").read_bytes() == before


# ---- class 6: odd numbers ---------------------------------------------------------------------
@pytest.mark.parametrize("args, match", [
    (["--max-steps", "0"], "--max-steps: expected a whole number >= 1"),
    (["--seed", "-1"], "--seed: expected a seed"),
    (["--seed", str(2**70)], "--seed: expected a seed"),
    (["--ess", "nan"], "--ess: expected a finite number > 0"),
    (["--ess", "-5"], "--ess: expected a finite number > 0"),
    (["--checkpoint-every", "0"], "--checkpoint-every: expected a finite number > 0"),
])
def test_class6_odd_cli_numbers_exit_2_with_one_error_line(tmp_path, capsys, monkeypatch, args, match):
    monkeypatch.setattr(fitting_module, "fit", _no_fit)
    with pytest.raises(SystemExit) as exc:
        main(["fit", MODEL, "electroadhesion_synthetic", "--out", str(tmp_path / "r"), *args])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert match in err[-1] and err[-1].startswith("skinfit fit: error: argument")
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("kwargs, match", [
    ({"rng": -1}, "rng: expected a seed"), ({"rng": 2**70}, "rng: expected a seed"),
    ({"max_steps": 0}, "max_steps: expected a whole number > 0"),
    ({"ess_target": float("nan")}, "ess_target: expected a finite number > 0"),
])
def test_class6_fit_refuses_odd_settings_before_the_map(monkeypatch, kwargs, match):
    monkeypatch.setattr(run_module, "find_map", _no_fit)
    with pytest.raises(InputError, match=match):
        skinfit.fit(MODEL, "electroadhesion_synthetic", **kwargs)


@pytest.mark.parametrize("value", [float("nan"), -0.02, 0.0, float("inf")])
def test_class6_nan_or_negative_constant_refused(tmp_path, value):
    ds = skinfit.load_dataset("electroadhesion_synthetic")
    model = skinfit.load_model(MODEL)
    with pytest.raises(InputError, match=r"constants\.R: expected a finite number > 0"):
        Posterior(model, skinfit.load_priors(MODEL), ds, constants={"R": value})
    card = (ROOT / "models" / f"{MODEL}.toml").read_text()
    text = card.replace("R = { value = 0.02,", f"R = {{ value = {value!r},")
    assert text != card
    (tmp_path / "m.toml").write_text(text)
    with pytest.raises(InputError, match=r"m\.toml: constants\.R: expected a finite number > 0"):
        skinfit.load_model(str(tmp_path / "m.toml"))


def test_class6_prior_bounds_1e13_apart_refused(tmp_path, monkeypatch):
    text = (ROOT / "priors" / f"{MODEL}.toml").read_text().replace("bounds = [0.0, 2.0]",
                                                                   "bounds = [0.5, 0.5000000000001]")
    (tmp_path / "p.toml").write_text(text)
    monkeypatch.setattr(run_module, "find_map", _no_fit)
    with pytest.raises(InputError, match=r"p\.toml: mu\.bounds: bounds \[0\.5, 0\.5000000000001\] are 1e-13 apart"):
        skinfit.fit(MODEL, "electroadhesion_synthetic", priors=str(tmp_path / "p.toml"))
