"""`skinfit demo`: the README's main job."""

import json

import pytest

import skinfit
from skinfit.cli import main
from skinfit.demo import demo_plan


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


def test_demo_fits_compares_and_reports(tmp_path, capsys, monkeypatch):
    from skinfit import report as report_module

    drawn = []  # per-fit figures the report process draws itself (one figure worker: in this process)
    render = report_module._render_one
    monkeypatch.setattr(report_module, "MAX_FIGURE_WORKERS", 1)

    def counted(i):
        if report_module._JOBS[i]["fit"] is not None:
            drawn.append(i)
        return render(i)

    monkeypatch.setattr(report_module, "_render_one", counted)
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--dataset", "electroadhesion_synthetic", "--jobs", "2"]) == 0
    text = capsys.readouterr().out
    assert "ranked by evidence" in text and "report:" in text
    report = out / "report"
    assert (report / "index.html").exists() and (report / "comparison_electroadhesion_synthetic.csv").exists()
    # every fit's figures were drawn by the fit workers into the figure store, and copied
    figures = sorted((report / "figures").glob("electroadhesion_synthetic_*.png"))
    assert len(figures) == 3 * len(report_module._FIGURES) and drawn == []
    assert all(f.with_suffix(".pdf").stat().st_size > 0 for f in figures)
    plan = json.loads((report / "demo_plan.json").read_text())
    assert [p["model"] for p in plan] == ["electroadhesion", "electroadhesion_coulomb", "electroadhesion_empirical"]
    from skinfit.compare import loo

    for p in plan:  # every fit converged and carries its evidence and LOO for later reports
        fit = skinfit.load_fit(out / p["dataset"] / p["model"] / "fit.nc")
        assert fit.converged, p["model"]
        assert "bridge" in json.loads(fit.idata.attrs["evidence"])
        assert fit.summary_stored  # the report reads the summary table instead of computing it
        # computed in the worker before saving: the numbers ArviZ gives on the saved file
        cached, fresh = json.loads(fit.attrs["loo"]), loo(fit)
        assert cached["elpd"] == pytest.approx(float(fresh.elpd), rel=1e-12)
        assert cached["se"] == pytest.approx(float(fresh.se), rel=1e-12)
    # a second run reuses the saved fits
    assert main(["demo", "--out", str(out), "--dataset", "electroadhesion_synthetic"]) == 0
    assert "(3 already done" in capsys.readouterr().out
    # ... but not under another sampler (the same seed would give other samples)
    from skinfit import demo, sampling

    monkeypatch.setattr(sampling, "TAU_KEEP", 5.0)
    item = next(p for p in plan if p["model"] == "electroadhesion")
    assert demo._reuse(out / item["dataset"] / item["model"] / "fit.nc", item, {}) is None
