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
from popdata import write_population

import skinfit
from skinfit.analysis.groups import derive_seed
from skinfit.apps.campaign import load_campaign, run_campaign
from skinfit.apps.cli import main

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
    proc = subprocess.Popen([sys.executable, "-m", "skinfit", "campaign", str(path), "--workers", "1"],
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
     r"scheduler: expected 'local' or a Dask scheduler's address like tcp://HOST:PORT"),
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
    from skinfit.inference import sampling

    data, _ = write_population(tmp_path, n_subjects=1)
    path = _campaign(tmp_path, data.name, "sampler")
    assert list(run_campaign(path, echo=lambda *a: None)["status"]) == ["done"]
    monkeypatch.setattr(sampling, "INDEPENDENCE_SUBSTEPS", 2)
    assert list(run_campaign(path, echo=lambda *a: None)["status"]) == ["done"]
    assert list(run_campaign(path, echo=lambda *a: None)["status"]) == ["complete"]


# ---- issue 21: class 1 (wrong data fitted silently), class 2 (results lost or mixed up), class 4 ----
def _rows(data):
    """Per subject, the tangential forces (N) read straight from the CSV."""
    rows = {}
    for line in (data / "data.csv").read_text().splitlines()[1:]:
        subject, _, _, ft = line.split(",")
        rows.setdefault(subject, []).append(float(ft) * 1e-3)
    return rows


def test_class1_absolute_path_whose_id_is_a_shipped_ones_fits_the_given_file(tmp_path):
    import json

    data, _ = write_population(tmp_path, n_subjects=1, name="electroadhesion_synthetic")  # the shipped id
    path = tmp_path / "c.toml"
    path.write_text(f'schema_version = 1\nseed = 3\nout = "out"\nmodels = ["electroadhesion_coulomb"]\n'
                    f'datasets = ["{data.resolve()}"]\n[fit]\ness = 100\nmax_steps = 4000\n')
    table = run_campaign(path, workers=1, echo=lambda *a: None)
    assert list(table["status"]) == ["done"]
    card = str((data / "dataset.toml").resolve())
    fit = skinfit.load_fit(tmp_path / "out" / table["path"][0])
    np.testing.assert_allclose(fit.idata["observed_data"]["tangential_force"].values, _rows(data)["S01"],
                               rtol=1e-12)  # 4 rows of this file, not the shipped 216
    sha = skinfit.load_dataset(card).sha256
    assert json.loads(fit.attrs["source"]) == {"path": card, "sha256": sha}
    task = json.loads((tmp_path / "out" / table["path"][0]).parent.joinpath("task.json").read_text())
    assert task["spec"]["dataset_ref"] == card and task["spec"]["sha256"]["dataset"] == sha
    index = json.loads((tmp_path / "out" / "index.json").read_text())
    assert index[0]["dataset_path"] == card and index[0]["dataset_sha256"] == sha


def test_class1_two_datasets_with_one_id_are_refused(tmp_path):
    data, _ = write_population(tmp_path, n_subjects=1, name="electroadhesion_synthetic")
    path = tmp_path / "c.toml"
    path.write_text(f'schema_version = 1\nseed = 3\nout = "out"\nmodels = ["electroadhesion_coulomb"]\n'
                    f'datasets = ["electroadhesion_synthetic", "{data}"]\n')
    with pytest.raises(skinfit.InputError, match=r"datasets\[1\]: dataset id 'electroadhesion_synthetic' .*is also "
                       r"the id of datasets\[0\]"):
        load_campaign(path)


def test_class1_a_saved_fit_of_other_data_is_not_reused_and_is_reported(tmp_path):
    data, _ = write_population(tmp_path, n_subjects=2)
    path = _campaign(tmp_path, data.name, "stale")
    first = run_campaign(path, workers=1, echo=lambda *a: None)
    # S02's folder now holds S01's result, with S02's own task.json beside it
    s01, s02 = (tmp_path / "stale" / p for p in first["path"])
    s02.write_bytes(s01.read_bytes())
    said = []
    again = run_campaign(path, workers=1, echo=said.append)
    assert list(again["status"]) == ["complete", "done"]
    assert any("stale" in s and "subject=S02" in s and "holds the fit of group 'subject=S01'" in s for s in said)
    assert skinfit.load_fit(s02).attrs["group"] == "subject=S02"
    # edited data: every fit is reported stale (recorded hash differs) and fitted again
    csv = data / "data.csv"
    csv.write_text(csv.read_text().replace("S01,0,200.0000,", "S01,0,200.0001,"))
    said.clear()
    assert list(run_campaign(path, workers=1, echo=said.append)["status"]) == ["done", "done"]
    assert sum("fitted to data with sha256" in s for s in said) == 2


def test_class2_input_error_pickles_with_its_message_and_fields():
    import pickle

    exc = skinfit.InputError("d/data.csv", "expected a force >= 0 (got -0.3 mN)", field="normal_force", row=7)
    back = pickle.loads(pickle.dumps(exc))
    assert type(back) is skinfit.InputError and str(back) == str(exc) == \
        "d/data.csv: normal_force, row 7: expected a force >= 0 (got -0.3 mN)"
    assert (back.where, back.what, back.field, back.row) == ("d/data.csv", exc.what, "normal_force", 7)


def test_class2_a_bad_dataset_in_a_worker_reports_its_message_and_the_others_complete(tmp_path):
    good, _ = write_population(tmp_path, n_subjects=2, name="good")
    bad, _ = write_population(tmp_path, n_subjects=1, name="bad", seed=9)
    path = tmp_path / "c.toml"
    path.write_text('schema_version = 1\nseed = 3\nout = "out"\nmodels = ["electroadhesion_coulomb"]\n'
                    'datasets = ["good", "bad"]\nby = ["subject"]\n[fit]\ness = 100\n')
    campaign = load_campaign(path)
    (bad / "data.csv").write_text((bad / "data.csv").read_text().replace(",0,", ",zero,", 1))  # edited after
    table = run_campaign(campaign, workers=2, echo=lambda *a: None)
    assert list(table["status"][:2]) == ["done", "done"]
    assert table["status"][2].startswith("failed: InputError: ") and "data.csv" in table["status"][2]
    assert "voltage" in table["status"][2] and "row 1" in table["status"][2]


def test_class2_two_campaigns_differing_in_one_option_never_share_dask_keys(tmp_path):
    from skinfit.apps.campaign import task_key

    data, _ = write_population(tmp_path, n_subjects=2)
    a = load_campaign(_campaign(tmp_path, data.name, "a"))
    b = load_campaign(_campaign(tmp_path, data.name, "b"))
    keys_a = {task_key(t) for t in a.tasks}
    assert len(keys_a) == 2 and keys_a.isdisjoint(task_key(t) for t in b.tasks)
    text = _campaign(tmp_path, data.name, "c").read_text().replace('out = "c"', 'out = "a"').replace(
        "ess = 100", "ess = 120")
    (tmp_path / "c.toml").write_text(text)  # same out and seeds, one option differs
    assert keys_a.isdisjoint(task_key(t) for t in load_campaign(tmp_path / "c.toml").tasks)
    assert keys_a == {task_key(t) for t in load_campaign(tmp_path / "a.toml").tasks}  # stable


def test_class2_a_campaign_refuses_an_out_in_use(tmp_path):
    from skinfit.inference.checkpoint import CheckpointLock

    data, _ = write_population(tmp_path, n_subjects=1)
    path = _campaign(tmp_path, data.name, "busy")
    with CheckpointLock(tmp_path / "busy" / "campaign"):
        with pytest.raises(skinfit.InputError, match=rf"busy: is in use by pid {os.getpid()} "):
            run_campaign(path, echo=lambda *a: None)
    assert not (tmp_path / "busy" / "index.json").exists()


def test_class1_a_campaign_never_drops_results_from_their_index(local_run, tmp_path, refused):
    """A campaign refuses, with one line and not a byte changed, an out whose results it would
    drop from their index: another campaign's fits it does not list, a run by groups of
    `skinfit fit --by` (whose index.json it would replace), a single fit; the same campaign,
    or one extending it, may run there. `skinfit fit --out` refuses a campaign's folder too."""
    import json

    from skinfit.apps.campaign import check_campaign_out

    folder, data, _, _ = local_run
    out = folder / "local"
    listed = [row["path"] for row in json.loads((out / "index.json").read_text())]

    def campaign(name, models, into):
        text = _campaign(tmp_path, data, name).read_text()
        text = text.replace('models = ["electroadhesion_coulomb"]', f"models = {json.dumps(models)}")
        (tmp_path / f"{name}.toml").write_text(text.replace(f'out = "{name}"', f'out = "{into}"'))
        return tmp_path / f"{name}.toml"

    refused(["campaign", str(campaign("other", ["electroadhesion_empirical"], out))], out,
            f"holds 3 fit(s) of another campaign that other.toml does not list (e.g. {listed[0]}): they would drop "
            "out of the index; give the campaign another out, or list them in it, or remove them (nothing was written)")
    for models in (["electroadhesion_coulomb"], ["electroadhesion_coulomb", "electroadhesion_empirical"]):
        check_campaign_out(load_campaign(campaign("more", models, out)))  # itself, or extended: no objection
    quick = ["--ess", "50", "--max-steps", "300", "--quiet"]
    refused(["fit", "electroadhesion_coulomb", str(data), "--by", "subject", "--out", str(out), *quick], out,
            "holds a campaign's results (index.json of skinfit campaign): give the run by groups another --out "
            "(nothing was written)")
    refused(["fit", "electroadhesion_coulomb", str(data), "--out", str(out), *quick], out,
            "holds a campaign's results (index.json of skinfit campaign): give a single fit another --out "
            "(nothing was written)")

    run, single = tmp_path / "run", tmp_path / "single"
    run.mkdir()
    (run / "index.json").write_text(json.dumps({"model": "electroadhesion_coulomb", "by": ["subject"],
                                                "dataset_sha256": "0" * 64, "fits": []}))
    refused(["campaign", str(campaign("into_run", ["electroadhesion_coulomb"], run))], run,
            "holds a run by groups of electroadhesion_coulomb (index.json of skinfit fit --by): give the campaign "
            "another out (nothing was written)")
    single.mkdir()
    (single / "fit.nc").write_bytes(b"a fit")
    refused(["campaign", str(campaign("into_single", ["electroadhesion_coulomb"], single))], single,
            "holds a single fit (fit.nc): give the campaign another out (nothing was written)")
    odd = tmp_path / "odd"
    odd.mkdir()
    (odd / "index.json").write_text("3")  # JSON, but neither kind of index
    with pytest.raises(skinfit.InputError, match="not a campaign's index skinfit can read"):
        check_campaign_out(load_campaign(campaign("into_odd", ["electroadhesion_coulomb"], odd)))


def test_class4_ids_with_path_syntax_are_refused_before_any_write(tmp_path):
    data, _ = write_population(tmp_path / "d", n_subjects=1)
    card = data / "dataset.toml"
    model = tmp_path / "m.toml"
    model.write_text((Path(skinfit.__file__).resolve().parents[1] / "models" / "electroadhesion_coulomb.toml")
                     .read_text().replace('id = "electroadhesion_coulomb"', 'id = "../../m"'))
    # refused when the card is read (an id is a name: skinfit.io.models.check_id) or, for an id
    # that got past it, by the campaign's own write-side check; either way the id is named
    cases = [('["electroadhesion_coulomb"]', "../../x", r"'\.\./\.\./x'"),
             ('["electroadhesion_coulomb"]', "/tmp/abs", r"'/tmp/abs'"),
             ('["electroadhesion_coulomb"]', "a/b", r"'a/b'"),
             (f'["{model}"]', "population", r"'\.\./\.\./m'")]
    for models, data_id, match in cases:
        head, _, rest = card.read_text().split("\n", 2)
        card.write_text(f'{head}\nid = "{data_id}"\n{rest}')
        path = tmp_path / "c.toml"
        path.write_text(f'schema_version = 1\nseed = 3\nout = "o/out"\nmodels = {models}\n'
                        f'datasets = ["{data}"]\nby = ["subject"]\n[fit]\ness = 100\n')
        with pytest.raises(skinfit.InputError, match=match):
            run_campaign(path, echo=lambda *a: None)
        assert not (tmp_path / "o").exists()


def test_class4_inside_refuses_paths_that_leave_out(tmp_path):
    from skinfit.analysis.groups import inside

    assert inside(tmp_path / "out", tmp_path / "out" / "m" / "d" / "fit.nc") == (tmp_path / "out/m/d/fit.nc").resolve()
    for bad in ("../x", "m/../../x", "/etc/x"):
        with pytest.raises(skinfit.InputError, match="outside the output folder"):
            inside(tmp_path / "out", tmp_path / "out" / bad)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "link").symlink_to(tmp_path)
    with pytest.raises(skinfit.InputError, match="outside the output folder"):
        inside(tmp_path / "out", tmp_path / "out" / "link" / "fit.nc")


def test_class4_write_side_check_refuses_ids_the_card_reader_would_pass_on():
    """The campaign's own guard (skinfit.io.campaign_file.check_name) refuses path syntax even when an id
    reaches it by another route than a card (e.g. a Dataset built in Python)."""
    from skinfit.io.campaign_file import check_name

    assert check_name("electroadhesion_synthetic", "dataset id", "c.toml") == "electroadhesion_synthetic"
    for bad in ("../../x", "/tmp/abs", "a/b", "..", ".hidden", "a b", ""):
        with pytest.raises(skinfit.InputError, match="cannot name a result folder"):
            check_name(bad, "dataset id", "c.toml")


def _map_failure_campaign(tmp_path):
    """The electroadhesion model on two 20-row datasets: the shipped data's first rows ("good")
    and the same with a zero normal force in row 1 ("zero": every prior draw impossible there,
    so its MAP fails with MAPError(message, result))."""
    from worker_jobs import zero_force

    zero_force(tmp_path, rows=20)
    good = tmp_path / "good"
    good.mkdir()
    src = Path(skinfit.__file__).resolve().parents[1] / "datasets" / "electroadhesion_synthetic"
    (good / "dataset.toml").write_text((src / "dataset.toml").read_text().replace(
        'id = "electroadhesion_synthetic"', 'id = "good"'))
    (good / "data.csv").write_text("\n".join((src / "data.csv").read_text().splitlines()[:21]) + "\n")
    path = tmp_path / "c.toml"
    path.write_text('schema_version = 1\nseed = 3\nout = "out"\nmodels = ["electroadhesion"]\n'
                    'datasets = ["zero", "good"]\n[fit]\ness = 40\nmax_steps = 600\n')
    return path


def test_failing_fit_never_touches_another_map_error_on_the_default_executor(tmp_path, capsys):
    """Issue 39 point 8: one dataset's MAP fails (MAPError, whose __init__ takes a result) on
    the default executor (spawned processes). The other fit is saved and indexed, the failing
    one is reported with its own one-line error (not BrokenProcessPool), the run exits 1; a
    rerun keeps the saved fit and reports the same error again. Each fit ran with one BLAS
    thread."""
    path = _map_failure_campaign(tmp_path)
    assert main(["campaign", str(path), "--workers", "2"]) == 1
    printed = capsys.readouterr().out
    out = tmp_path / "out"
    table = pd.read_csv(out / "index.csv").set_index("dataset")
    assert table.loc["good", "status"] == "done" and (out / table.loc["good", "path"]).is_file()
    assert table.loc["good", "threads"] == 1  # the worker's BLAS/OpenMP thread limit as the fit ended
    error = table.loc["zero", "status"]
    assert error.startswith("failed: MAPError: ") and "MAP failed" in error and "data row(s) 1 (normal_force = 0" in error
    assert "BrokenProcessPool" not in printed and "MAP failed" in printed
    assert f"failed {('electroadhesion / zero')}: MAPError: " in (out / "campaign.log").read_text()
    mtime = (out / table.loc["good", "path"]).stat().st_mtime_ns
    assert main(["campaign", str(path), "--workers", "2"]) == 1  # the rerun completes
    again = pd.read_csv(out / "index.csv").set_index("dataset")
    assert again.loc["good", "status"] == "complete" and again.loc["zero", "status"] == error
    assert (out / table.loc["good", "path"]).stat().st_mtime_ns == mtime


@pytest.mark.parametrize("argv, message", [
    (["--scheduler", "banana"], "--scheduler: expected 'local' or a Dask scheduler's address like tcp://HOST:PORT"),
    (["--scheduler", "tcp://localhost"], "--scheduler: expected 'local' or a Dask scheduler's address"),
])
def test_scheduler_argument_is_refused_in_one_line_before_any_work(tmp_path, capsys, argv, message):
    data, _ = write_population(tmp_path, n_subjects=1)
    path = _campaign(tmp_path, data.name, "sched")
    capsys.readouterr()
    assert main(["campaign", str(path), *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"skinfit: error: {message}") and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "sched").exists()


def test_scheduler_without_dask_installed_is_refused_in_one_line(tmp_path, capsys, monkeypatch):
    data, _ = write_population(tmp_path, n_subjects=1)
    path = _campaign(tmp_path, data.name, "nodask")
    monkeypatch.setitem(sys.modules, "distributed", None)  # as without the dask extra
    capsys.readouterr()
    assert main(["campaign", str(path), "--scheduler", "local"]) == 2
    err = capsys.readouterr().err
    assert err == "skinfit: error: distributed is not installed: install skinfit[dask] (pip install 'skinfit[dask]')\n"
    assert not (tmp_path / "nodask").exists()


@pytest.mark.parametrize("kwargs, match", [
    ({"scheduler": "banana"}, r"^--scheduler: expected 'local'"),
    ({"workers": 0}, r"^--workers: expected a whole number >= 1 \(got 0\)"),
    ({"workers": -1}, r"^--workers: expected a whole number >= 1 \(got -1\)"),
    ({"workers": "2"}, r"^--workers: expected a whole number >= 1 \(got '2'\)"),
    ({"threads": 0}, r"^--threads: expected a whole number >= 1 \(got 0\)"),
])
def test_run_campaign_arguments_are_checked_before_any_work(tmp_path, kwargs, match):
    data, _ = write_population(tmp_path, n_subjects=1)
    path = _campaign(tmp_path, data.name, "args")
    with pytest.raises(skinfit.InputError, match=match):
        run_campaign(path, echo=lambda *a: None, **kwargs)
    assert not (tmp_path / "args").exists()


@pytest.mark.parametrize("line, match", [
    ('scheduler = "banana://host:1"', r"scheduler: expected 'local' or a Dask scheduler's address"),
    ("threads = 0", r"threads: expected a whole number >= 1 \(got 0\)"),
    ("workers = true", r"workers: expected an integer"),
])
def test_campaign_file_scheduler_and_counts_are_checked(tmp_path, line, match):
    data, _ = write_population(tmp_path, n_subjects=1)
    path = _campaign(tmp_path, data.name, "file", extra=line)
    with pytest.raises(skinfit.InputError, match=match) as info:
        load_campaign(path)
    assert str(path) in str(info.value)
