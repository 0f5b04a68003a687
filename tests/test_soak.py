"""Soak tests of campaigns (issue 21, class 2: results never lost or mixed up).

A campaign killed with SIGKILL at random moments and rerun, and campaigns sharing one Dask
scheduler, must end with every fit present exactly once, each equal (posterior draws bit for
bit) to that of an uninterrupted run, no partial result counted as complete, no temporary file
left over and no file written outside the campaign's ``out``.

The full soak (``-m slow``: >= 50 fits, 20 random kills of the whole process group, two
concurrent campaigns on one LocalCluster) wrote bench/results/soak.md; the default suite runs
a small deterministic version (one kill of the main process only at a fixed point, two
concurrent campaigns of two fits each).
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import psutil
import pytest
from popdata import write_population

import skinfit
from skinfit.apps.campaign import load_campaign, run_campaign, run_fit

SEED = int(os.environ.get("SKINFIT_TEST_SEED", "21"))


def _campaign(folder, name, data, *, seed=5, ess=100, models=("electroadhesion_coulomb",)):
    path = folder / f"{name}.toml"
    path.write_text(f'schema_version = 1\nseed = {seed}\nout = "{name}"\nmodels = {json.dumps(list(models))}\n'
                    f'datasets = ["{data.name}"]\nby = ["subject"]\n[fit]\ness = {ess}\nmax_steps = 4000\n')
    return path


def _spawn(path, *args):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "skinfit", "campaign", str(path), *args],
                            start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)


def _files(folder):
    return {p for p in Path(folder).rglob("*") if p.is_file()}


def _draws(out):
    """``{(model, group): {variable: posterior draws}}`` of every fit listed in ``out/index.csv``."""
    table = pd.read_csv(out / "index.csv", keep_default_na=False)
    result = {}
    for row in table.itertuples():
        post = skinfit.load_fit(out / row.path).idata["posterior"].to_dataset()
        result[(row.model, row.group)] = {v: post[v].values for v in post.data_vars}
    return result


def check_complete(campaign, reference):
    """Every task once in the index, complete, its file present once, draws equal to ``reference``."""
    out = campaign.out
    index = json.loads((out / "index.json").read_text())
    keys = [(r["model"], r["dataset"], r["group"]) for r in index]
    assert len(keys) == len(set(keys)) == len(campaign.tasks)
    assert {r["status"] for r in index} <= {"done", "complete"}, {r["status"] for r in index}
    fits = sorted(out.rglob("fit.nc"))
    assert fits == sorted(Path(t["path"]) for t in campaign.tasks)
    assert not list(out.rglob("*.tmp")), "a temporary file was left over"
    draws = _draws(out)
    assert draws.keys() == reference.keys()
    for key, variables in reference.items():
        for name, values in variables.items():
            np.testing.assert_array_equal(draws[key][name], values, err_msg=f"{key} {name}")


def _reference(folder, data, name, **kw):
    """The draws of an uninterrupted run of a campaign like ``name``: each fit run in this
    process, one after the other (:func:`skinfit.apps.campaign.run_fit`, no executor)."""
    campaign = load_campaign(_campaign(folder, f"{name}_ref", data, **kw))
    result = {}
    for task in campaign.tasks:
        run_fit(task)
        post = skinfit.load_fit(task["path"]).idata["posterior"].to_dataset()
        result[(task["model"], task["group"])] = {v: post[v].values for v in post.data_vars}
    return result


def _wait_for_fit(out, deadline=300):
    end = time.time() + deadline
    while not list(out.glob("**/task.json")) and time.time() < end:
        time.sleep(0.05)
    assert list(out.glob("**/task.json")), "no fit finished before the deadline"


def _concurrent_on_one_scheduler(folder, data, options, reference):
    """Run one campaign per ``options`` entry at once on one LocalCluster; check each."""
    from distributed import LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0")
    try:
        paths = [_campaign(folder, name, data, **kw) for name, kw in options.items()]
        procs = [_spawn(p, "--scheduler", cluster.scheduler_address) for p in paths]
        for proc in procs:
            _, err = proc.communicate(timeout=900)
            assert proc.returncode == 0, err.decode()
    finally:
        cluster.close()
    for path, name in zip(paths, options):
        check_complete(load_campaign(path), reference[name])


@pytest.mark.parametrize("executor", [[], ["--scheduler", "local"]], ids=["processes", "dask-local-cluster"])
def test_class2_killed_main_process_stops_its_workers_and_the_rerun_equals_an_uninterrupted_run(tmp_path, executor):
    data, _ = write_population(tmp_path, n_subjects=3, seed=SEED)
    reference = _reference(tmp_path, data, "run")
    before = _files(tmp_path)
    path = _campaign(tmp_path, "run", data)
    campaign = load_campaign(path)
    proc = _spawn(path, "--workers", "2", *executor)
    try:
        _wait_for_fit(campaign.out)  # the fixed point: the first result written
        workers = psutil.Process(proc.pid).children(recursive=True)
        assert workers
        os.kill(proc.pid, signal.SIGKILL)  # the main process only: its workers must not write on
        proc.wait()
        gone, alive = psutil.wait_procs(workers, timeout=60)
        assert not alive, f"workers still running after their campaign was killed: {alive}"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    table = run_campaign(path, workers=2, echo=lambda *a: None)
    assert "complete" in set(table["status"])
    check_complete(campaign, reference)
    assert all(p.is_relative_to(campaign.out) for p in _files(tmp_path) - before - {path})


def test_class2_two_campaigns_on_one_dask_scheduler_differing_in_one_option(tmp_path):
    data, _ = write_population(tmp_path, n_subjects=2, seed=SEED)
    options = {"ess100": {"ess": 100}, "ess120": {"ess": 120}}  # same seeds and groups: once the same Dask keys
    reference = {name: _reference(tmp_path, data, name, **kw) for name, kw in options.items()}
    before = _files(tmp_path)
    _concurrent_on_one_scheduler(tmp_path, data, options, reference)
    outs = [tmp_path / name for name in options]
    assert all(any(p.is_relative_to(o) for o in outs) for p in _files(tmp_path) - before
               if p.suffix != ".toml")


@pytest.mark.slow
def test_soak_random_sigkills_and_concurrent_campaigns(tmp_path):
    """>= 50 fits on 2 processes, SIGKILLed (the whole process group) at 20 random moments and
    rerun each time; then two campaigns with different options at once on one LocalCluster."""
    rng = np.random.default_rng(SEED)
    lines = []
    data, _ = write_population(tmp_path, n_subjects=52, rows=4, seed=SEED)
    models = ("electroadhesion_coulomb",)
    t0 = time.perf_counter()
    reference = _reference(tmp_path, data, "soak", models=models)
    lines.append(f"uninterrupted reference run: {len(reference)} fits in {time.perf_counter() - t0:.1f} s "
                 "(one after the other in the test process)")
    before = _files(tmp_path)
    path = _campaign(tmp_path, "soak", data, models=models)
    campaign = load_campaign(path)
    assert len(campaign.tasks) >= 50
    temps_seen = 0
    log = campaign.out / "campaign.log"

    def count(word):
        return log.read_text().count(f" {word} ") if log.exists() else 0

    for kill in range(20):
        # a random moment: odd kills 0-12 s after this run's start (python start-up, workers
        # starting, first fits), even kills 0-2.5 s after this run's first finished fit (fits
        # and saves under way); the campaign process and its workers are killed together
        anchor = "start" if kill % 2 == 0 else "done"
        delay = float(rng.uniform(0.0, 12.0 if anchor == "start" else 2.5))
        seen = count(anchor)
        proc = _spawn(path, "--workers", "2")
        end = time.time() + 300
        while count(anchor) == seen and proc.poll() is None and time.time() < end:
            time.sleep(0.02)
        time.sleep(delay)
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        temps = list(campaign.out.rglob("*.tmp"))
        temps_seen += len(temps)
        done = len(list(campaign.out.rglob("task.json")))
        lines.append(f"kill {kill + 1:2d} {delay:5.2f} s after the run's first {anchor:5s}: rc {proc.returncode}, "
                     f"{done:2d} of "
                     f"{len(campaign.tasks)} fits recorded, {len(temps)} temporary file(s) left by the kill")
    proc = _spawn(path, "--workers", "2")
    _, err = proc.communicate(timeout=1800)
    assert proc.returncode == 0, err.decode()
    log = (campaign.out / "campaign.log").read_text()
    removed = log.count(" removed ")
    runs = log.count(" start ")
    lines.append(f"final run: rc 0; campaign.log: {runs} starts, {log.count(' done ')} fits done in all, "
                 f"{log.count(' stale ')} stale fits refitted, {removed} temporary files of killed writers removed "
                 f"({temps_seen} seen after the kills, counting repeats)")
    check_complete(campaign, reference)
    outside = [p for p in _files(tmp_path) - before - {path} if not p.is_relative_to(campaign.out)]
    assert not outside, outside
    lines.append(f"every fit present once ({len(campaign.tasks)}), posterior draws bit-identical to the "
                 "uninterrupted run, no temporary file left, no file outside out")

    t0 = time.perf_counter()
    options = {"dask_ess100": {"ess": 100, "models": models}, "dask_ess150": {"ess": 150, "models": models}}
    reference = {"dask_ess100": {k: v for k, v in _draws(campaign.out).items()}}
    reference["dask_ess150"] = _reference(tmp_path, data, "dask_ess150", ess=150, models=models)
    _concurrent_on_one_scheduler(tmp_path, data, options, reference)
    lines.append(f"two campaigns of {len(campaign.tasks)} fits (ess 100 and ess 150, same seeds and groups) at "
                 f"once on one LocalCluster (2 workers): both complete, each equal to its uninterrupted run "
                 f"({time.perf_counter() - t0:.1f} s with the ess-150 reference)")
    report = os.environ.get("SKINFIT_SOAK_REPORT")
    if report:
        Path(report).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
