"""Recovery of the generating parameters of every shipped simulated dataset (issue 3's table).

    skinfit demo --out runs/demo
    python bench/recovery_table.py runs/demo

For each dataset, the fit of the model that generated it (as the demo fits it: rows and
splits of ``skinfit.apps.demo.DEMO_OPTIONS``): per parameter with a recorded truth, the truth,
posterior mean, central 95% interval and whether the truth is inside; and per fit the wall
time, minimum bulk ESS and maximum R-hat. Writes ``bench/results/recovery.md``.
"""

import argparse
import re
import sys
from pathlib import Path

import numpy as np

import skinfit
from skinfit import __version__

RESULTS = Path(__file__).resolve().parent / "results"


def truths(dataset, rows):
    """parameter display name -> generating value, from the dataset card's provenance."""
    prov = dataset.provenance
    out = {}
    gen = prov.get("generating_parameters")
    if isinstance(gen, dict):
        for name, v in gen.items():
            if isinstance(v, dict):
                out.update({f"{name}[{level}]": float(x) for level, x in v.items()})
            else:
                out[name] = float(v)
    for name, levels in prov.get("generating_split", {}).items():
        out.update({f"{name}[{level}]": float(x) for level, x in levels.items()})
    subject = (rows or {}).get("subject")
    if subject is not None:
        out.update({k: float(v) for k, v in prov.get("subjects", {}).get(subject, {}).items()})
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", help="directory written by `skinfit demo --out`")
    args = p.parse_args(argv)
    from skinfit.apps.demo import DEMO_OPTIONS

    lines = [f"# Recovery on the shipped simulated datasets (issue 3)\n\nskinfit {__version__}; "
             f"`python bench/recovery_table.py {' '.join(argv or sys.argv[1:])}` on the fits of `skinfit demo` "
             f"(its seed and options). Truths from each dataset card's `[provenance]`; SI units.\n"]
    head = ["\n| dataset | model | rows | wall s | steps | min bulk ESS | max R-hat (ArviZ, kept draws, derived quantities included) | "
            "max R-hat (skinfit's gate, as recorded in the fit) | truths inside 95% |",
            "|---|---|---|---|---|---|---|---|---|"]
    tables = []
    for path in sorted(Path(args.runs).glob("*/*/fit.nc")):
        ds_id, model_id = path.parts[-3], path.parts[-2]
        dataset = skinfit.load_dataset(ds_id)
        if dataset.provenance.get("generator") != model_id:
            continue
        fit = skinfit.load_fit(path)
        summary = fit.summary()
        post = fit.idata["posterior"].to_dataset()
        known = truths(dataset, DEMO_OPTIONS.get(ds_id, {}).get("rows"))
        rows, inside = [], 0
        for name in summary.index:
            if name not in known:
                continue
            base, level = (re.fullmatch(r"(\w+)\[(.+)\]", name).groups() if "[" in name else (name, None))
            da = post[base]
            if level is not None:
                dim = [d for d in da.dims if d not in ("chain", "draw")][0]
                da = da.sel({dim: level})
            draws = np.asarray(da.values).ravel()
            lo, hi = np.quantile(draws, [0.025, 0.975])
            ok = lo < known[name] < hi
            inside += ok
            rows.append(f"| {name} | {known[name]:.4g} | {draws.mean():.4g} | [{lo:.4g}, {hi:.4g}] | "
                        f"{'yes' if ok else 'NO'} |")
        s, t = fit.attr("sampler"), fit.attr("timings")
        head.append(f"| {ds_id} | {model_id} | {max(fit.idata['observed_data'].sizes.values())} | "
                    f"{t['total_s']:.1f} | {s['n_steps']} | {summary['ess_bulk'].min():.0f} | "
                    f"{summary['r_hat'].max():.4f} | {s['rhat_max']:.4f} | {inside}/{len(rows)} |")
        tables += [f"\n## {model_id} on {ds_id}\n", "| parameter | truth | posterior mean | 95% interval | inside |",
                   "|---|---|---|---|---|", *rows]
    out = RESULTS / "recovery.md"
    out.write_text("\n".join(lines + head + tables) + "\n")
    print(out.read_text())


if __name__ == "__main__":
    main()
