"""Campaigns: validated files, derived seeds, identical results on processes, a Dask
LocalCluster and a real `dask scheduler` + `dask worker` cluster, restart after a kill."""

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import skinfit
from popdata import write_population
from skinfit.campaign import load_campaign, run_campaign
from skinfit.cli import main
from skinfit.groups import derive_seed

DASK = Path(sys.executable).parent / "dask"


def _campaign(folder, data, out, seed=3, extra=""):
    path = folder / f"{out}.toml"
    path.write_text(f'schema_version = 1\nseed = {seed}\nout = "{out}"\nmodels = ["electroadhesion_coulomb"]\n'
                    f'datasets = ["{data}"]\nby = ["subject"]\n{extra}\n[fit]\ness = 100\nmax_steps = 4000\n')
    return path


def _posteriors(out):
    table = pd.read_csv(out / "index.csv")
    return {row.group: skinfit.load_fit(out / row.path).idata["posterior"]["mu"].values for row in table.itertuples()}


@pytest.fixture(scope="module")
def local_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("campaign")
    data, _ = write_population(folder, n_subjects=3)
    path = _campaign(folder, data.name, "local")
    table = run_campaign(path, workers=2, echo=lambda *a: None)
    return folder, data, table, _posteriors(folder / "local")


def test_local_processes_index_and_seeds(local_run):
    folder, data, table, _ = local_run
    assert list(table["status"]) == ["done"] * 3 and table["converged"].all()
    assert list(table["group"]) == ["subject=S01", "subject=S02", "subject=S03"]
    for row in table.itertuples():
        assert row.seed == derive_seed(3, "electroadhesion_coulomb", "population", row.group)
        assert skinfit.load_fit(folder / "local" / row.path).idata.attrs["seed"] == row.seed
        assert row.peak_rss_mb > 50 and row.seconds > 0
    # a second run finds everything complete and runs nothing
    again = run_campaign(_campaign(folder, data.name, "local"), workers=2, echo=lambda *a: None)
    assert list(again["status"]) == ["complete"] * 3
    log = (folder / "local" / "campaign.log").read_text().split(" start ")
    assert " run " not in log[-1] and log[-1].count(" skip ") == 3


def test_dask_local_cluster_same_numbers(local_run):
    folder, data, _, reference = local_run
    table = run_campaign(_campaign(folder, data.name, "dask_local"), scheduler="local", workers=2,
                         echo=lambda *a: None)
    assert list(table["status"]) == ["done"] * 3
    assert len(set(table["worker"])) >= 1
    result = _posteriors(folder / "dask_local")
    assert result.keys() == reference.keys()
    for group in reference:
        np.testing.assert_array_equal(result[group], reference[group])


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop(proc):
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


@pytest.mark.slow
def test_real_dask_cluster_same_numbers(local_run, capsys):
    from distributed import Client

    folder, data, _, reference = local_run
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    started = []
    try:
        started.append(subprocess.Popen([str(DASK), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                                         "--dashboard-address", ":0"], start_new_session=True,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        for _ in range(2):
            started.append(subprocess.Popen([str(DASK), "worker", address, "--nthreads", "1", "--nworkers", "1",
                                             "--host", "127.0.0.1", "--dashboard-address", ":0"],
                                            start_new_session=True, stdout=subprocess.DEVNULL,
                                            stderr=subprocess.DEVNULL))
        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=60)
        path = _campaign(folder, data.name, "cluster")
        assert main(["campaign", str(path), "--scheduler", address]) == 0
        assert "3 of 3 fits complete" in capsys.readouterr().out
        table = pd.read_csv(folder / "cluster" / "index.csv")
        assert list(table["status"]) == ["done"] * 3
        result = _posteriors(folder / "cluster")
        for group in reference:
            np.testing.assert_array_equal(result[group], reference[group])
    finally:
        for proc in reversed(started):
            _stop(proc)


def test_kill_midway_then_restart_runs_only_unfinished(tmp_path):
    data, _ = write_population(tmp_path, n_subjects=4)
    path = _campaign(tmp_path, data.name, "killed", seed=8)
    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "skinfit.cli", "campaign", str(path), "--workers", "1"],
                            start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.time() + 180
        while not list(out.glob("**/task.json")) and time.time() < deadline:
            time.sleep(0.1)
        os.killpg(proc.pid, signal.SIGKILL)  # the campaign and its worker process
        proc.wait()
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    campaign = load_campaign(path)
    finished = {t["group"] for t in campaign.tasks if (Path(t["path"]).parent / "task.json").exists()}
    assert 1 <= len(finished) < 4, "the kill should land after the first result and before the last"
    mtimes = {t["group"]: Path(t["path"]).stat().st_mtime_ns for t in campaign.tasks if t["group"] in finished}
    table = run_campaign(path, workers=1, echo=lambda *a: None)
    ran = {line.split(" / ")[-1] for line in (out / "campaign.log").read_text().split(" start ")[-1].splitlines()
           if " run " in line}
    assert ran == {t["group"] for t in campaign.tasks} - finished
    assert set(table.loc[table["status"] == "complete", "group"]) == finished
    assert set(table.loc[table["status"] == "done", "group"]) == ran
    for t in campaign.tasks:
        if t["group"] in finished:
            assert Path(t["path"]).stat().st_mtime_ns == mtimes[t["group"]]


@pytest.mark.parametrize("text, match", [
    ('seed = 1\nout = "o"\nmodels = ["electroadhesion_coulomb"]\ndatasets = ["electroadhesion_synthetic"]\nworkerz = 2',
     r"unknown keys \['workerz'\]"),
    ('seed = "1"\nout = "o"\nmodels = ["electroadhesion_coulomb"]\ndatasets = ["electroadhesion_synthetic"]',
     r"seed: expected an integer \(got '1'\)"),
    ('seed = 1\nout = "o"\nmodels = ["nope"]\ndatasets = ["electroadhesion_synthetic"]',
     r"models\[0\]: nope: no such model"),
    ('seed = 1\nout = "o"\nmodels = ["electroadhesion_coulomb"]\ndatasets = ["electroadhesion_synthetic", "nada"]',
     r"datasets\[1\]: nada: no such dataset"),
    ('seed = 1\nout = "o"\nmodels = ["electroadhesion_coulomb"]\ndatasets = ["electroadhesion_synthetic"]\nby = ["finger"]',
     r"by: dataset 'electroadhesion_synthetic' has no column 'finger'"),
    ('seed = 1\nout = "o"\nmodels = ["electroadhesion_coulomb"]\ndatasets = ["electroadhesion_synthetic"]\n[fit]\nnoise = "cauchy"',
     r"fit.noise: expected one of normal, student_t, lognormal"),
    ('seed = 1\nout = "o"\nmodels = ["electroadhesion_coulomb"]\ndatasets = ["electroadhesion_synthetic"]\n[fit]\ness = 0',
     r"fit.ess: expected a number > 0"),
    ('seed = 1\nout = "o"\nmodels = ["electroadhesion_coulomb"]\ndatasets = ["electroadhesion_synthetic"]\n[split]\nelectroadhesion_coulomb = {alpha = "voltage"}',
     r"split.electroadhesion_coulomb.alpha: model 'electroadhesion_coulomb' has no parameter 'alpha'"),
    ('seed = 1\nout = "o"\nmodels = ["electroadhesion_coulomb"]\ndatasets = ["electroadhesion_synthetic"]\nscheduler = "localhost"',
     r"scheduler: expected 'local' or an address"),
])
def test_validation_names_file_and_field(tmp_path, text, match):
    path = tmp_path / "bad.toml"
    path.write_text("schema_version = 1\n" + text + "\n")
    with pytest.raises(skinfit.InputError, match=match) as info:
        load_campaign(path)
    assert str(path) in str(info.value)


def test_shipped_example_is_valid():
    campaign = load_campaign(Path(skinfit.__file__).resolve().parents[1] / "campaigns" / "example.toml")
    assert len(campaign.tasks) == 9 and campaign.tasks[0]["group"] == "voltage=0"
    assert len({t["seed"] for t in campaign.tasks}) == 9


def test_edited_data_makes_the_fit_run_again(tmp_path):
    """A finished fit is reused only while its model card, prior file and data are unchanged."""
    data, _ = write_population(tmp_path, n_subjects=1)
    path = _campaign(tmp_path, data.name, "edit")
    assert list(run_campaign(path, echo=lambda *a: None)["status"]) == ["done"]
    assert list(run_campaign(path, echo=lambda *a: None)["status"]) == ["complete"]
    csv = next(p for p in data.iterdir() if p.suffix == ".csv")
    lines = csv.read_text().splitlines()
    last = lines[-1].split(",")
    last[-1] = str(float(last[-1]) * 1.01)
    csv.write_text("\n".join(lines[:-1] + [",".join(last)]) + "\n")
    assert list(run_campaign(path, echo=lambda *a: None)["status"]) == ["done"]


def test_another_sampler_makes_the_fit_run_again(tmp_path, monkeypatch):
    """A finished fit is not reused by a skinfit whose sampler differs (same seed, other samples)."""
    from skinfit import sampling

    data, _ = write_population(tmp_path, n_subjects=1)
    path = _campaign(tmp_path, data.name, "sampler")
    assert list(run_campaign(path, echo=lambda *a: None)["status"]) == ["done"]
    monkeypatch.setattr(sampling, "INDEPENDENCE_SUBSTEPS", 2)
    assert list(run_campaign(path, echo=lambda *a: None)["status"]) == ["done"]
    assert list(run_campaign(path, echo=lambda *a: None)["status"]) == ["complete"]
