"""``skinfit demo``: every shipped dataset fitted with its model and the model's competing
variants, compared by evidence and LOO, and written up as one static report.

Fits run in parallel worker processes (``--jobs``, default one per core); each fit's seed is
derived from the demo seed and the (dataset, model) pair, so results do not depend on the
number of workers or the order in which fits finish. A fit already saved under ``--out``
(same seed) is reused, so an interrupted demo continues where it stopped. The report's figures
are drawn while this process compares the fits and runs the population; a report folder that
already holds a figure drawn from the same content keeps it.
"""

import json
import os
import time
import zlib
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

from skinfit.analysis.compare import compare, loo_record
from skinfit.analysis.evidence import evidence
from skinfit.errors import InputError
from skinfit.inference.sampling import sampler_settings
from skinfit.inference.workers import limited_threads
from skinfit.io.arguments import check_count, check_output_folder
from skinfit.io.data import list_datasets, load_dataset
from skinfit.io.models import load_model
from skinfit.io.paths import explicit_search_path, set_search_path
from skinfit.io.priors import load_priors
from skinfit.report.groups import group_analyses
from skinfit.report.html import claim_report_folder, write_report
from skinfit.results.fit import load_fit
from skinfit.results.fitting import fit

__all__ = ["DEMO_OPTIONS", "demo_plan", "run_demo"]

#: How the demo fits each shipped dataset, where the default (all rows, nothing split) does not
#: match the study design. ``rows`` selects rows by column value; ``split`` maps parameter ->
#: column, as ``skinfit.fit(split=...)``.
DEMO_OPTIONS = {
    # the electroadhesion paper fits one alpha per voltage; a shared alpha is the default and the demo keeps it
    "contact_area_synthetic": {"rows": {"subject": "S01"}, "by": "subject",
                               "why": "Huloux, Willemet & Wiertlewski fit one subject at a time; "
                                      "the model on every subject "
                                      "(as --by subject) for the population and contrasts"},
    "wavy_synthetic": {"split": {"r": "wavelength", "s": "wavelength"},
                       "why": "Fujii, Okamoto & Yamada needed smaller contact parameters r, s at lambda = 20 mm"},
    "textured_synthetic": {"split": {"beta_h": "material"},
                           "why": "the Biotribology 2019 paper varies the hysteresis fraction beta_h per silicone "
                                  "grade"},
}


def demo_plan(seed):
    """The (dataset, model, seed, options) fits of the demo, in a stable order."""
    plan = []
    for ds_id in list_datasets():
        ds = load_dataset(ds_id)
        if not ds.model:
            continue
        options = DEMO_OPTIONS.get(ds_id, {})
        for model_id in (ds.model, *load_model(ds.model).variants):
            split = {p: c for p, c in options.get("split", {}).items()
                     if p in load_model(model_id).parameter_names}
            key = zlib.crc32(f"{ds_id}/{model_id}".encode())
            fit_seed = int(np.random.SeedSequence([seed, key]).generate_state(1)[0])
            rows = options.get("rows", {})
            data = _select(ds, rows)
            plan.append({"dataset": ds_id, "model": model_id, "seed": fit_seed, "split": split,
                         "rows": rows, "n_rows": len(data), "why": options.get("why", ""),
                         "max_steps": options.get("max_steps", {}).get(model_id, 20000),
                         "sha256": _inputs(data, model_id)})
        if options.get("by"):  # the dataset's model on every other group too (``group`` set)
            col = options["by"]
            first = str(options.get("rows", {}).get(col))
            for level in dict.fromkeys(ds.frame[col].astype(str)):
                if level == first:
                    continue
                key = zlib.crc32(f"{ds_id}/{ds.model}/{col}={level}".encode())
                fit_seed = int(np.random.SeedSequence([seed, key]).generate_state(1)[0])
                data = _select(ds, {col: level})
                plan.append({"dataset": ds_id, "model": ds.model, "seed": fit_seed, "split": {},
                             "rows": {col: level}, "n_rows": len(data), "why": "",
                             "group": f"{col}={level}", "max_steps": 20000, "sha256": _inputs(data, ds.model)})
    return plan


def _inputs(data, model_id):
    """The sha256 of a plan item's data (its selected rows), model card and prior file, as
    this process finds them: a saved fit is reused, and a worker's fit kept, only when made
    from these."""
    # the prior file's identity: its distributions are checked where it is used (the fit), so
    # that a demo whose fits are all reused does not import scipy.stats for them
    return {"dataset": data.sha256, "model": load_model(model_id).sha256,
            "priors": load_priors(model_id, check_mass=False).sha256}


def _path(out, item):
    """Where a plan item's fit is saved: OUT/dataset/model[/group]/fit.nc."""
    base = Path(out) / item["dataset"] / item["model"]
    return (base / item["group"].replace("=", "-") if item.get("group") else base) / "fit.nc"


def _select(ds, rows):
    if not rows:
        return ds
    mask = np.ones(len(ds), dtype=bool)
    for col, value in rows.items():
        mask &= ds.frame[col].astype(str).to_numpy() == str(value)
    label = ",".join(f"{c}={v}" for c, v in rows.items())
    return ds.subset(mask, label)


def _run_one(item, path):
    """Fit one plan item, compute what the comparison reads (log Z by bridge sampling and
    PSIS-LOO, cached in the fit's attributes, each from its own fixed seed) and save it (top
    level: runs in a worker process, so these costs are spread over the workers too), with
    one BLAS/OpenMP thread unless the environment sets otherwise (one worker per core:
    :func:`skinfit.inference.workers.worker_threads`)."""
    with limited_threads():
        return _fit_one(item, path)


def _fit_one(item, path):
    t0 = time.perf_counter()
    ds = _select(load_dataset(item["dataset"]), item["rows"])
    found = _inputs(ds, item["model"])
    if found != item["sha256"]:  # another search path (a spawned worker without --path) or an edited card
        which = ", ".join(k for k in found if found[k] != item["sha256"][k])
        raise InputError(item["dataset"], f"the fit worker found other {which} for {item['model']} than the demo "
                                          "planned with; nothing was fitted")
    result = fit(item["model"], ds, rng=item["seed"], split=item["split"] or None,
                 max_steps=item["max_steps"])
    if not item.get("group"):  # a compared fit (see run_demo)
        _comparison_records(result)
    result.save(path)
    return {"model": item["model"], "dataset": item["dataset"], "seconds": time.perf_counter() - t0,
            "converged": result.converged}


def _comparison_records(fit):
    """Evidence and LOO of ``fit`` into its attributes; True when either was computed now."""
    had = bool(json.loads(fit.attrs.get("evidence", "{}")).get("bridge")) and "loo" in fit.attrs
    evidence(fit)
    loo_record(fit)
    return not had


def _reuse(path, item):
    """The saved fit of this item, when it has the item's seed and was made on the data, model
    card and priors the item was planned with (their sha256) and the same sampler settings; else
    None (an edited file, or another sampler, and the item is fitted again)."""
    if not path.exists():
        return None
    try:
        saved = load_fit(path)
        attrs = saved.attrs
        same = (int(attrs.get("seed", -1)) == item["seed"]
                and all(attrs.get(f"{k}_sha256") == v for k, v in item["sha256"].items())
                and saved.attr("sampler").get("settings") == sampler_settings())
    except Exception:  # a damaged or foreign file: fit again
        return None
    return saved if same else None


def run_demo(out="runs/demo", report="runs/demo/report", *, seed=1, jobs=None, datasets=None, echo=print):
    """Fit, compare and report every shipped dataset; returns the report's index.html path."""
    out = check_output_folder(out, "demo", "out")
    report = check_output_folder(report, "demo", "report")
    seed = check_count(seed, "demo", "seed", lo=0, hi=2**63 - 1)
    jobs = check_count(jobs, "demo", "jobs", optional=True)
    plan = demo_plan(seed)
    unknown = sorted(set(datasets or ()) - {p["dataset"] for p in plan})
    if unknown:
        raise InputError("demo", f"no shipped dataset {', '.join(map(repr, unknown))} in the demo (shipped: "
                         f"{', '.join(sorted({p['dataset'] for p in plan}))})", field="dataset")
    claim_report_folder(Path(report))  # a folder of the user's files is refused now, not after the fits
    plan = [p for p in plan if datasets is None or p["dataset"] in datasets]
    paths = [_path(out, p) for p in plan]
    reused = [_reuse(path, p) for p, path in zip(plan, paths)]
    todo = [(p, path) for p, path, f in zip(plan, paths, reused) if f is None]
    todo.sort(key=lambda t: -t[0]["n_rows"])  # larger fits first: the workers finish together
    echo(f"skinfit demo: {len(plan)} fits of {len({p['dataset'] for p in plan})} SIMULATED shipped "
         f"datasets ({len(plan) - len(todo)} already done under {out})")
    for _p, path, f in zip(plan, paths, reused):  # the demo's folder is its own: a fit of other settings is
        if f is None and path.exists():             # replaced, and said so
            echo(f"  replacing {path}: not made with this demo's seed, cards, data and sampler settings")
    for p in plan:
        extra = f"  [{p['why']}]" if p["why"] else ""
        echo(f"  {p['dataset']:<28} {p['model'] + (' ' + p['group'] if p.get('group') else ''):<30} "
             f"seed {p['seed']}{extra}")
    jobs = jobs or min(len(todo), os.cpu_count() or 1) or 1
    if todo:
        # workers started by spawn or forkserver (macOS; Linux from Python 3.14) inherit no
        # --path: given it, they find the cards this process planned with (checked: _run_one)
        with ProcessPoolExecutor(max_workers=jobs, initializer=set_search_path,
                                 initargs=(explicit_search_path(),)) as pool:
            futures = {pool.submit(_run_one, p, path): (p, path) for p, path in todo}
            for fut in as_completed(futures):
                r = fut.result()
                flag = "converged" if r["converged"] else "NOT CONVERGED (see the report)"
                echo(f"  done {r['dataset']} / {r['model']}: {r['seconds']:.1f} s, {flag}")
    fits = {f"{p['dataset']} / {p['model']}" + (f" / {p['group']}" if p.get("group") else ""):
            f if f is not None else load_fit(path) for p, path, f in zip(plan, paths, reused)}

    def analyses():  # while the report draws the figures its folder does not hold
        comparisons, populations, contrasts = _analyses(fits, plan, out, seed, echo)
        return {"comparison": comparisons or None, "populations": populations, "contrasts": contrasts}

    index = write_report(fits, report, title="skinfit demo: the shipped (simulated) datasets", analyses=analyses)
    (Path(report) / "demo_plan.json").write_text(json.dumps(plan, indent=1) + "\n")
    echo(f"\nreport: {index}")
    return index


def _analyses(fits, plan, out, seed, echo):
    """The comparison tables of each dataset's competing models, the populations and the
    contrasts of the demo's fits (each population kept under ``out``, with the fits it is
    drawn from, whichever report folder shows it)."""
    comparisons, computed = {}, set()
    for ds_id in dict.fromkeys(p["dataset"] for p in plan):
        items = [(name, f, p) for (name, f), p in zip(fits.items(), plan)
                 if p["dataset"] == ds_id and not p.get("group")]  # the competing models on the same rows
        if len(items) > 1:
            computed |= {name for name, f, _ in items if _comparison_records(f)}
            comparisons[ds_id] = compare([f for _, f, _ in items])
            echo(f"\n{ds_id}: ranked by evidence\n"
                 + comparisons[ds_id][["log_z", "log_z_se", "log_bf_vs_best", "strength", "elpd_loo"]]
                 .to_string(float_format="{:.4g}".format))
    for (name, f), p in zip(fits.items(), plan):
        if name in computed or not f.summary_stored:  # saved by an older demo: keep what it lacked with it
            f.save(_path(out, p))
    t0 = time.perf_counter()
    populations, contrasts = group_analyses(fits, seed=seed, echo=echo, cache_dir=Path(out) / ".cache")
    if populations or contrasts:
        echo(f"\npopulation of {', '.join(populations) or 'none'} and {len(contrasts)} contrast table(s): "
             f"{time.perf_counter() - t0:.1f} s")
    return comparisons, populations, contrasts
