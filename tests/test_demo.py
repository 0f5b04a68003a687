"""`skinfit demo`: the README's main job."""

import json

import pytest

import skinfit
from skinfit.apps.cli import main
from skinfit.apps.demo import demo_plan


def test_plan_covers_every_shipped_dataset_with_its_variants():
    plan = demo_plan(seed=1)
    for ds_id in skinfit.list_datasets():
        model = skinfit.load_model(skinfit.load_dataset(ds_id).model)
        fitted = [p["model"] for p in plan if p["dataset"] == ds_id and not p.get("group")]
        assert fitted == [model.id, *model.variants]
    # the contact-area model on every subject (S01 with the variants above), as --by subject
    subjects = sorted(p["rows"]["subject"] for p in plan if p["dataset"] == "contact_area_synthetic"
                      and p["model"] == "contact_area")
    frame = skinfit.load_dataset("contact_area_synthetic").frame
    assert subjects == sorted(frame["subject"].astype(str).unique()) and len(subjects) == 13
    seeds = [p["seed"] for p in plan]
    assert len(set(seeds)) == len(seeds)
    assert [p["seed"] for p in demo_plan(seed=1)] == seeds != [p["seed"] for p in demo_plan(seed=2)]


_REUSED_DEMO = """
import sys
from skinfit.apps.cli import main

assert main(["demo", "--out", sys.argv[1], "--dataset", "electroadhesion_synthetic"]) == 0
"""


def test_demo_fits_compares_and_reports(tmp_path, capsys, monkeypatch):
    from skinfit.report import figures as report_figures

    drawn = []  # per-fit figures the report process draws itself (one figure worker: in this process)
    render = report_figures.render_one
    monkeypatch.setattr(report_figures, "MAX_FIGURE_WORKERS", 1)

    def counted(i):
        if report_figures._JOBS[i]["fit"] is not None:
            drawn.append(report_figures._JOBS[i]["path"].name)
        return render(i)

    monkeypatch.setattr(report_figures, "render_one", counted)
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--dataset", "electroadhesion_synthetic", "--jobs", "2"]) == 0
    text = capsys.readouterr().out
    assert "ranked by evidence" in text and "report:" in text
    report = out / "report"
    assert (report / "index.html").exists() and (report / "comparison_electroadhesion_synthetic.csv").exists()
    # every fit's figures drawn by the report
    figures = sorted((report / "figures").glob("electroadhesion_synthetic_*.png"))
    assert len(figures) == 3 * len(report_figures.FIGURES) and sorted(drawn) == [f.name for f in figures]
    assert all(f.with_suffix(".pdf").stat().st_size > 0 for f in figures)
    plan = json.loads((report / "demo_plan.json").read_text())
    assert [p["model"] for p in plan] == ["electroadhesion", "electroadhesion_coulomb", "electroadhesion_empirical"]
    from skinfit.analysis.compare import loo

    for p in plan:  # every fit converged and carries its evidence and LOO for later reports
        fit = skinfit.load_fit(out / p["dataset"] / p["model"] / "fit.nc")
        assert fit.converged, p["model"]
        assert "bridge" in json.loads(fit.idata.attrs["evidence"])
        assert fit.summary_stored  # the report reads the summary table instead of computing it
        # computed in the worker before saving: the numbers ArviZ gives on the saved file
        cached, fresh = json.loads(fit.attrs["loo"]), loo(fit)
        assert cached["elpd"] == pytest.approx(float(fresh.elpd), rel=1e-12)
        assert cached["se"] == pytest.approx(float(fresh.se), rel=1e-12)
    # a second run reuses the saved fits, and the report folder keeps their figures
    drawn.clear()
    assert main(["demo", "--out", str(out), "--dataset", "electroadhesion_synthetic"]) == 0
    assert "(3 already done" in capsys.readouterr().out and drawn == []
    # ... and in a new process, which finds every fit done and rewrites the report
    import subprocess
    import sys

    run = subprocess.run([sys.executable, "-c", _REUSED_DEMO, str(out)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "(3 already done" in run.stdout
    # ... but not under another sampler (the same seed would give other samples)
    from skinfit.apps import demo
    from skinfit.inference import sampling

    monkeypatch.setattr(sampling, "TAU_KEEP", 5.0)
    item = next(p for p in plan if p["model"] == "electroadhesion")
    assert demo._reuse(out / item["dataset"] / item["model"] / "fit.nc", item) is None


_SPAWNED_DEMO = """
import multiprocessing, sys
from skinfit.apps.cli import main
if __name__ == "__main__":
    multiprocessing.set_start_method(sys.argv[1], force=True)
    sys.exit(main(["--path", sys.argv[2], "demo", "--dataset", "electroadhesion_synthetic", "--jobs", "2",
                   "--out", sys.argv[3]]))
"""


def test_demo_workers_started_by_spawn_fit_the_data_found_through_path(tmp_path):
    """``--path`` puts a user's folder first; a user's dataset there shadows the shipped one of the
    same id. Fit workers started by spawn (macOS; forkserver on Linux from Python 3.14) inherit no
    module state, and used to fit the shipped data while the demo planned with the user's: every
    fit must be made on the user's 120 rows, not the shipped 216."""
    import os
    import shutil
    import subprocess
    import sys

    shipped = skinfit.load_dataset("electroadhesion_synthetic")
    user = tmp_path / "mine" / "datasets" / "electroadhesion_synthetic"
    user.mkdir(parents=True)
    card = skinfit.io.paths.locate("datasets", "electroadhesion_synthetic")
    shutil.copy(card, user / "dataset.toml")
    lines = (card.parent / "data.csv").read_text().splitlines()
    (user / "data.csv").write_text("\n".join(lines[:121]) + "\n")  # the header and the first 120 rows
    script = tmp_path / "spawned_demo.py"
    script.write_text(_SPAWNED_DEMO)
    out = tmp_path / "demo"
    subprocess.run([sys.executable, str(script), "spawn", str(tmp_path / "mine"), str(out)], check=True,
                   capture_output=True, env={**os.environ, "MPLBACKEND": "Agg"})
    mine = skinfit.load_dataset(user)
    assert mine.sha256 != shipped.sha256 and len(mine) == 120
    for model in ("electroadhesion", "electroadhesion_coulomb", "electroadhesion_empirical"):
        fit = skinfit.load_fit(out / "electroadhesion_synthetic" / model / "fit.nc")
        assert fit.attrs["dataset_sha256"] == mine.sha256, model
        assert fit.idata["observed_data"].sizes["obs_id"] == 120


def test_a_fit_worker_that_finds_other_inputs_than_planned_fits_nothing(tmp_path):
    from skinfit.apps import demo
    from skinfit.errors import InputError

    item = next(p for p in demo_plan(seed=1) if p["model"] == "electroadhesion_coulomb")
    path = tmp_path / "fit.nc"
    for which in ("dataset", "model", "priors"):
        other = dict(item, sha256=dict(item["sha256"], **{which: "0" * 64}))
        with pytest.raises(InputError, match=rf"the fit worker found other {which} for electroadhesion_coulomb"):
            demo._run_one(other, path)
        assert not path.exists()


def test_a_demo_into_a_folder_of_the_users_files_stops_before_fitting(tmp_path):
    from skinfit.apps.demo import run_demo
    from skinfit.errors import InputError

    site = tmp_path / "site"
    site.mkdir()
    (site / "index.html").write_text("<html>my page</html>")
    with pytest.raises(InputError, match="holds files a skinfit report did not write"):
        run_demo(tmp_path / "runs", site, echo=lambda *a: None)
    assert not (tmp_path / "runs").exists() and [p.name for p in site.iterdir()] == ["index.html"]
