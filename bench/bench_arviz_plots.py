"""arviz-plots 1.x against skinfit's hand-written diagnostic figures (issue 23), figure by figure.

    .venv/bin/python bench/bench_arviz_plots.py [--work /tmp/skinfit-bench-azplots] [--repeats 5]
                                                [--only trace,pair] [--skip-fresh]

The fits are made once under --work (``skinfit fit`` with seed 1; reused when present):
electroadhesion on electroadhesion_synthetic (8 sampled scalars), electroadhesion_coulomb on it
(4, the small case), textured_surface with beta_h split by material (a per-fit forest) and
contact_area ``--by subject`` (13 fits: the across-fit forest). Every figure is drawn at the size
the report shows it (at most ``skinfit.plots.MAX_WIDTH`` wide) and saved as the report saves it
(``skinfit.plots.write_figure_files``: PNG at ``plots.DPI``, plus PDF). Per (figure, variant,
fit): wall and CPU seconds to draw + save, the median of ``--repeats`` after one warm-up in this
process, and the first call in a fresh process including the imports of the plotting code
(``skinfit.report.html``/``skinfit.plots``, ``arviz_plots``; the fit is loaded before the clock
starts); the layout problems of tests/layout.py (texts outside the canvas, overlapping, < 8 pt);
colours of lines, markers and fills outside a colour-blind-safe set (Okabe & Ito's palette,
greys). Writes a Markdown table to stdout and the drawn PNGs to --work/figs for a look.

"tuned" variants are arviz-plots with the keyword arguments found to meet the layout rules at
the report's size (see VARIANTS); "defaults" only sets the figure size.
"""

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "tests"))

FITS = {  # name -> skinfit fit arguments
    "ea": ["electroadhesion", "electroadhesion_synthetic"],
    "eac": ["electroadhesion_coulomb", "electroadhesion_synthetic"],
    "tex": ["textured_surface", "textured_synthetic", "--split", "beta_h=material"],
    "ca_by": ["contact_area", "contact_area_synthetic", "--by", "subject"],
}
#: Okabe & Ito's palette (as skinfit.plots.style.COLOURS, with its yellow) and neutral greys/black/white.
SAFE = {"#0072b2", "#d55e00", "#009e73", "#cc79a7", "#e69f00", "#56b4e9", "#f0e442", "#000000", "#666666",
        "#ffffff"}


# ---- fits ------------------------------------------------------------------------------------
def ensure_fits(work):
    for name, args in FITS.items():
        out = work / name
        if (out / "fit.nc").exists() or (out / "index.json").exists():
            continue
        cmd = [sys.executable, "-m", "skinfit", "fit", *args, "--out", str(out), "--seed", "1", "--quiet"]
        print("making", " ".join(cmd[2:]), file=sys.stderr)
        subprocess.run(cmd, check=True, capture_output=True)


def load_subjects(work):
    """The contact_area subject fits, label (S01 ...) -> Fit."""
    import skinfit

    paths = sorted((work / "ca_by").glob("subject-*/fit.nc"))
    if not paths:
        raise SystemExit(f"no subject fits under {work / 'ca_by'}: remove it and run again")
    return {p.parent.name.split("-")[1]: skinfit.load_fit(p) for p in paths}


def load_context(work):
    """Loaded fits, completed and summarised as the report does before it draws."""
    import skinfit

    ctx = {}
    for name in ("ea", "eac", "tex"):
        ctx[name] = skinfit.load_fit(work / name / "fit.nc")
    ctx["subjects"] = load_subjects(work)
    for fit in [ctx["ea"], ctx["eac"], ctx["tex"], *ctx["subjects"].values()]:
        fit.complete()
        fit.summary()
    return ctx


# ---- figures --------------------------------------------------------------------------------
def _azp_figure(pc):
    """The matplotlib Figure of a PlotCollection, taken out of pyplot's registry."""
    import matplotlib.pyplot as plt

    fig = pc.viz["figure"].item()
    plt.close(fig)
    return fig


def _rc():
    """The rc settings of the tuned variants: Okabe & Ito's colours as the cycle, 8-9 pt text."""
    from cycler import cycler

    from skinfit import plots

    return {"axes.prop_cycle": cycler(color=list(plots.style.COLOURS)), "font.size": 9, "axes.titlesize": 9,
            "axes.labelsize": 9, "xtick.labelsize": 8, "ytick.labelsize": 8, "legend.fontsize": 8}


def _fig_kwargs(width, height, constrained=True):
    kw = {"figsize": (width, height), "figsize_units": "inches"}
    if constrained:
        kw["layout"] = "constrained"
    return kw


def _walker_groups(fit, n_groups=4):
    """The posterior with emcee's walkers pooled into ``n_groups`` chains, as skinfit's rank
    histograms (and, since this bench, its plot_rank) group them."""
    from skinfit import plots

    return plots.rank.walker_groups(fit, n_groups)


def _walkers(dt, n=8):
    """The posterior of ``n`` evenly spaced walkers (skinfit's trace shows 8 of them)."""
    import xarray as xr

    post = dt["posterior"].to_dataset()
    shown = np.linspace(0, post.sizes["chain"] - 1, n).astype(int)
    return xr.DataTree.from_dict({"posterior": post.isel(chain=shown)})


def _n_slots(fit):
    return len(fit.attr("slots"))


# skinfit's sizes, as skinfit.plots computes them (the arviz variants are drawn at the same size)
def _size_trace(fit):
    return 9.4, 1.35 * _n_slots(fit) + 0.9


def _size_pair(fit):
    s = min(1.6 * _n_slots(fit) + 1.4, 9.4)
    return s, s


def _size_grid(fit, ncols=4):
    n = _n_slots(fit)
    c = min(ncols, n)
    return min(3.0 * c, 9.4), 2.3 * -(-n // c) + 0.7


def sk_trace(fit, ctx):
    from skinfit import plots
    return plots.plot_trace(fit)


def az_trace_default(fit, ctx):
    import arviz_plots as azp
    return _azp_figure(azp.plot_trace_dist(fit.idata, backend="matplotlib",
                                           figure_kwargs=_fig_kwargs(*_size_trace(fit), constrained=False)))


def _tuned(fit, what, draw, **rc):
    """An arviz-plots figure drawn by ``draw()`` under the tuned rc settings (plus ``rc``),
    titled "MODEL on DATASET: what"."""
    import matplotlib as mpl

    with mpl.rc_context({**_rc(), **rc}):
        fig = _azp_figure(draw())
        fig.suptitle(f"{fit.model_id} on {fit.dataset_id}: {what}", fontsize=10)
    return fig


def az_trace_tuned(fit, ctx):
    import arviz_plots as azp

    return _tuned(fit, "traces (8 walkers)", lambda: azp.plot_trace_dist(
        _walkers(fit.idata), backend="matplotlib", compact=False, combined=True, kind="hist",
        figure_kwargs=_fig_kwargs(*_size_trace(fit)), visuals={"trace": {"linewidth": 0.6}}))


def az_rank_dist_tuned(fit, ctx):
    import arviz_plots as azp

    return _tuned(fit, "marginals and rank ECDF (4 walker groups)", lambda: azp.plot_rank_dist(
        _walker_groups(fit), backend="matplotlib", compact=False, combined=True, kind="hist",
        figure_kwargs=_fig_kwargs(*_size_trace(fit))))


def sk_rank(fit, ctx):
    from skinfit import plots
    return plots.plot_rank(fit)


def az_rank_default(fit, ctx):
    import arviz_plots as azp
    return _azp_figure(azp.plot_rank(fit.idata, backend="matplotlib",
                                     figure_kwargs=_fig_kwargs(*_size_grid(fit), constrained=False)))


def sk_pair(fit, ctx):
    from skinfit import plots
    return plots.plot_pair(fit)


def _max_subplots(n):
    from arviz_base import rcParams
    rcParams["plot.max_subplots"] = max(rcParams["plot.max_subplots"], n)


def az_pair_default(fit, ctx):
    import arviz_plots as azp
    _max_subplots(_n_slots(fit) ** 2)
    return _azp_figure(azp.plot_pair(fit.idata, backend="matplotlib",
                                     figure_kwargs=_fig_kwargs(*_size_pair(fit), constrained=False)))


def az_pair_tuned(fit, ctx):
    import arviz_plots as azp
    import matplotlib as mpl
    import xarray as xr

    _max_subplots(_n_slots(fit) ** 2)
    post = fit.group("posterior")
    draws = post.sizes["chain"] * post.sizes["draw"]
    thin = max(1, draws // 1500)  # skinfit's corner plot shows at most 1500 draws too
    pooled = (post.stack(sample=("chain", "draw")).isel(sample=slice(None, None, thin))
              .drop_vars(["chain", "draw", "sample"]).expand_dims(chain=1).rename(sample="draw"))
    pooled = pooled.assign_coords(chain=[0], draw=np.arange(pooled.sizes["draw"]))
    dt = xr.DataTree.from_dict({"posterior": pooled})
    mapv = xr.Dataset({k: v for k, v in fit.map.items() if k in post.data_vars})
    with mpl.rc_context({**_rc(), "xtick.labelsize": 8, "ytick.labelsize": 8}):
        pc = azp.plot_pair(dt, backend="matplotlib", marginal_kind="hist",
                           figure_kwargs=_fig_kwargs(*_size_pair(fit)),
                           visuals={"scatter": {"alpha": 0.25, "width": 0, "size": 2, "rasterized": True},
                                    "point_estimate": {"color": "#D55E00"}, "credible_interval": False,
                                    "point_estimate_text": False},
                           stats={"point_estimate": mapv})
        fig = _azp_figure(pc)
        short = mpl.ticker.FuncFormatter(lambda v, _: f"{v:.3g}")  # no offset text ("1e-7") to collide
        for ax in fig.axes:
            ax.tick_params(axis="x", labelrotation=90)
            for axis in (ax.xaxis, ax.yaxis):
                axis.set_major_locator(mpl.ticker.MaxNLocator(3, prune="both"))
                axis.set_major_formatter(short)
        d = _n_slots(fit)  # the marginals' density axis carries no information: no ticks
        grid = np.array(fig.axes[:d * d]).reshape(d, d) if len(fig.axes) >= d * d else None
        if grid is not None:
            for i in range(d):
                grid[i, i].set_yticks([])
        fig.suptitle(f"{fit.model_id} on {fit.dataset_id}: posterior draws (MAP in orange-red)", fontsize=10)
    return fig


def sk_prior_posterior(fit, ctx):
    from skinfit import plots
    return plots.plot_prior_posterior(fit)


def az_prior_posterior_default(fit, ctx):
    import arviz_plots as azp
    return _azp_figure(azp.plot_prior_posterior(fit.idata, backend="matplotlib",
                                                figure_kwargs=_fig_kwargs(*_size_grid(fit), constrained=False)))


def az_prior_posterior_tuned(fit, ctx):
    import arviz_plots as azp
    import matplotlib as mpl

    def draw():
        pc = azp.plot_prior_posterior(fit.idata, backend="matplotlib", col_wrap=4,
                                      figure_kwargs=_fig_kwargs(*_size_grid(fit)))
        for ax in pc.viz["figure"].item().axes:
            ax.xaxis.set_major_locator(mpl.ticker.MaxNLocator(4))
        return pc

    return _tuned(fit, "prior vs posterior", draw, **{"axes.formatter.limits": (-3, 4)})


def _across(ctx):
    """The 13 contact_area subjects (label -> Fit) and a population interval of m0 (lo, median, hi
    of the subject means: a stand-in of the right shape for the population row)."""
    fits = ctx["subjects"]
    means = [float(f.group("posterior")["m0"].mean()) for f in fits.values()]
    lo, mid, hi = np.quantile(means, [0.03, 0.5, 0.97])
    return fits, {"median": mid, "lo": lo, "hi": hi}


def sk_forest_across(fit, ctx):
    from skinfit import plots
    fits, pop = _across(ctx)
    return plots.plot_forest(fits, "m0", population=pop)


def az_forest_across_default(fit, ctx):
    import arviz_plots as azp
    fits, _ = _across(ctx)
    n = len(fits) + 1
    return _azp_figure(azp.plot_forest({k: f.idata for k, f in fits.items()}, var_names=["m0"], combined=True,
                                       backend="matplotlib",
                                       figure_kwargs=_fig_kwargs(6.4, 0.32 * n + 1.4, constrained=False)))


def az_forest_across_tuned(fit, ctx):
    """The subjects as a dimension of one posterior (each subject's draws pooled over walkers and
    cut to the shortest), so that each gets its own labelled row."""
    import arviz_plots as azp
    import matplotlib as mpl
    import xarray as xr

    fits, pop = _across(ctx)
    draws = [f.group("posterior")["m0"].values.ravel() for f in fits.values()]
    n = min(len(d) for d in draws)
    ds = xr.Dataset({"m0": (("chain", "draw", "subject"), np.stack([d[:n] for d in draws], axis=-1)[None])},
                    coords={"subject": list(fits), "chain": [0], "draw": np.arange(n)})
    with mpl.rc_context(_rc()):
        pc = azp.plot_forest(xr.DataTree.from_dict({"posterior": ds}), combined=True, backend="matplotlib",
                             ci_probs=[0.5, 0.94], labels=["subject"],
                             figure_kwargs=_fig_kwargs(6.4, 0.32 * (len(fits) + 1) + 1.4))
        fig = _azp_figure(pc)
        ax = fig.axes[-1]
        ax.axvspan(pop["lo"], pop["hi"], color="0.6", alpha=0.2, lw=0)
        ax.axvline(pop["median"], color="0.3", lw=0.8, ls="--")
        ax.set_xlabel("m0 [-]")
        fig.suptitle("m0 across fits and conditions (band: population 94%)", fontsize=10)
    return fig


def sk_forest_split(fit, ctx):
    from skinfit import plots
    return plots.plot_forest(ctx["tex"], "beta_h")


def az_forest_split_default(fit, ctx):
    import arviz_plots as azp
    n = ctx["tex"].group("posterior")["beta_h"].size // (ctx["tex"].group("posterior").sizes["chain"]
                                                          * ctx["tex"].group("posterior").sizes["draw"])
    return _azp_figure(azp.plot_forest(ctx["tex"].idata, var_names=["beta_h"], backend="matplotlib",
                                       figure_kwargs=_fig_kwargs(6.4, 0.32 * n + 1.4, constrained=False)))


def az_forest_split_tuned(fit, ctx):
    import arviz_plots as azp
    import matplotlib as mpl

    tex = ctx["tex"]
    post = tex.group("posterior")
    n = post["beta_h"].size // (post.sizes["chain"] * post.sizes["draw"])
    with mpl.rc_context(_rc()):
        pc = azp.plot_forest(tex.idata, var_names=["beta_h"], combined=True, backend="matplotlib",
                             ci_probs=[0.5, 0.94], labels=["material"],
                             figure_kwargs=_fig_kwargs(6.4, 0.32 * n + 1.4))
        fig = _azp_figure(pc)
        fig.axes[-1].set_xlabel("beta_h [-]")
        fig.suptitle("beta_h per material", fontsize=10)
    return fig


#: figure -> [(variant, function, fits it is drawn for)]
VARIANTS = {
    "trace": [("skinfit plot_trace", sk_trace, ("ea", "eac")),
              ("azp.plot_trace_dist, defaults", az_trace_default, ("ea", "eac")),
              ("azp.plot_trace_dist, tuned", az_trace_tuned, ("ea", "eac")),
              ("azp.plot_rank_dist, tuned", az_rank_dist_tuned, ("ea", "eac"))],
    "rank": [("skinfit plot_rank (= azp.plot_rank, tuned)", sk_rank, ("ea", "eac")),
             ("azp.plot_rank, defaults", az_rank_default, ("ea", "eac"))],
    "pair": [("skinfit plot_pair", sk_pair, ("ea", "eac")),
             ("azp.plot_pair, defaults", az_pair_default, ("ea", "eac")),
             ("azp.plot_pair, tuned", az_pair_tuned, ("ea", "eac"))],
    "prior_posterior": [("skinfit plot_prior_posterior", sk_prior_posterior, ("ea", "eac")),
                        ("azp.plot_prior_posterior, defaults", az_prior_posterior_default, ("ea", "eac")),
                        ("azp.plot_prior_posterior, tuned", az_prior_posterior_tuned, ("ea", "eac"))],
    "forest_across": [("skinfit plot_forest", sk_forest_across, ("subjects",)),
                      ("azp.plot_forest, defaults", az_forest_across_default, ("subjects",)),
                      ("azp.plot_forest, tuned", az_forest_across_tuned, ("subjects",))],
    "forest_split": [("skinfit plot_forest", sk_forest_split, ("tex",)),
                     ("azp.plot_forest, defaults", az_forest_split_default, ("tex",)),
                     ("azp.plot_forest, tuned", az_forest_split_tuned, ("tex",))],
}


# ---- measuring ------------------------------------------------------------------------------
def colours_outside(fig):
    """Colours of drawn lines, markers and fills outside SAFE (hex, sorted)."""
    import matplotlib.colors as mc
    from matplotlib.collections import Collection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    seen = set()
    for ax in fig.axes:
        for art in ax.get_children():
            cols = []
            if isinstance(art, Line2D) and art.get_visible():
                cols = [art.get_color(), art.get_markerfacecolor()]
            elif isinstance(art, Collection) and art.get_visible():
                cols = list(art.get_facecolors()) + list(art.get_edgecolors())
            elif isinstance(art, Patch) and art.get_visible() and art is not ax.patch:
                cols = [art.get_facecolor(), art.get_edgecolor()]
            for c in cols:
                try:
                    rgba = mc.to_rgba(c)
                except ValueError:
                    continue
                if rgba[3] == 0:
                    continue
                h = mc.to_hex(rgba[:3])
                r, g, b = mc.to_rgb(h)
                if h not in SAFE and not (abs(r - g) < 0.02 and abs(g - b) < 0.02):  # greys pass
                    seen.add(h)
    return sorted(seen)


def draw_once(func, fit, ctx, path):
    """Wall and CPU seconds of draw + save (PNG + PDF as the report writes them), and the figure."""
    from skinfit import plots

    w0, c0 = time.perf_counter(), time.process_time()
    fig = func(fit, ctx)
    plots.write_figure_files(fig, path)
    return time.perf_counter() - w0, time.process_time() - c0, fig


def fit_for(ctx, key):
    return None if key == "subjects" else ctx[key]


def measure(ctx, figs, repeats, only):
    from layout import layout_problems

    rows = []
    for figure, variants in VARIANTS.items():
        if only and figure not in only:
            continue
        for k, (variant, func, keys) in enumerate(variants):
            for key in keys:
                fit = fit_for(ctx, key)
                path = figs / f"{figure}_{k}_{key}.png"
                try:
                    _, _, fig = draw_once(func, fit, ctx, path)  # warm-up
                except Exception as e:  # the failure is the row's result
                    rows.append({"figure": figure, "variant": variant, "fit": key, "error": f"{type(e).__name__}: {e}"})
                    print(figure, variant, key, "ERROR", e, file=sys.stderr)
                    continue
                problems = layout_problems(fig)
                bad_colours = colours_outside(fig)
                size = tuple(round(float(v), 2) for v in fig.get_size_inches())
                walls, cpus = [], []
                for _ in range(repeats):
                    w, c, _ = draw_once(func, fit, ctx, path)
                    walls.append(w)
                    cpus.append(c)
                row = {"figure": figure, "variant": variant, "fit": key, "size": size,
                       "wall": statistics.median(walls), "cpu": statistics.median(cpus),
                       "layout": problems, "colours": bad_colours, "index": k}
                rows.append(row)
                print(f"{figure:16s} {variant:40s} {key:8s} {row['wall']:.2f} s wall {row['cpu']:.2f} s cpu "
                      f"{len(problems)} layout problems {problems[:2]} colours {bad_colours[:4]}", file=sys.stderr)
    return rows


def fresh(work, figure, k, key):
    """Child process: the first call, incl. importing the plotting code; prints JSON."""
    import skinfit

    ctx = {key: load_subjects(work) if key == "subjects" else skinfit.load_fit(work / key / "fit.nc")}
    for f in ([ctx[key]] if key != "subjects" else ctx["subjects"].values()):
        f.complete()
        f.summary()
    assert "matplotlib" not in sys.modules and "arviz_plots" not in sys.modules, "plotting imported too early"
    func = VARIANTS[figure][k][1]
    w0, c0 = time.perf_counter(), time.process_time()
    draw_once(func, fit_for(ctx, key), ctx, work / "figs" / f"fresh_{figure}_{k}_{key}.png")
    print(json.dumps({"wall": time.perf_counter() - w0, "cpu": time.process_time() - c0}))


def measure_fresh(work, rows):
    for row in rows:
        if "error" in row:
            continue
        out = subprocess.run([sys.executable, __file__, "--work", str(work), "--fresh",
                              f"{row['figure']}:{row['index']}:{row['fit']}"],
                             capture_output=True, text=True)
        if out.returncode:
            row["fresh"] = None
            print(out.stderr[-2000:], file=sys.stderr)
            continue
        row["fresh"] = json.loads(out.stdout.strip().splitlines()[-1])
        print(row["figure"], row["variant"], row["fit"], "fresh", row["fresh"], file=sys.stderr)


def table(rows):
    lines = ["| figure | variant | fit | size in | wall s | CPU s | fresh process wall / CPU s | layout problems "
             "(count: first) | colours outside the safe set |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['figure']} | {r['variant']} | {r['fit']} | | | | | fails: {r['error'][:160]} | |")
            continue
        fr = r.get("fresh")
        fresh_text = "" if "fresh" not in r else ("failed" if fr is None else f"{fr['wall']:.2f} / {fr['cpu']:.2f}")
        lay = f"{len(r['layout'])}" + (f": {r['layout'][0]}" if r["layout"] else "")
        lines.append(f"| {r['figure']} | {r['variant']} | {r['fit']} | {r['size'][0]} x {r['size'][1]} | "
                     f"{r['wall']:.2f} | {r['cpu']:.2f} | {fresh_text} | {lay.replace('|', '/')} | "
                     f"{', '.join(r['colours'][:6]) or 'none'}{' ...' if len(r['colours']) > 6 else ''} |")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", default="/tmp/skinfit-bench-azplots")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--only", default="", help="comma-separated figures: " + ",".join(VARIANTS))
    ap.add_argument("--skip-fresh", action="store_true", help="no fresh-process first calls")
    ap.add_argument("--json", help="also write the rows as JSON here")
    ap.add_argument("--fresh", help=argparse.SUPPRESS)
    args = ap.parse_args()
    work = Path(args.work)
    if args.fresh:
        figure, k, key = args.fresh.split(":")
        return fresh(work, figure, int(k), key)
    import os
    os.environ.setdefault("MPLBACKEND", "Agg")
    ensure_fits(work)
    figs = work / "figs"
    figs.mkdir(parents=True, exist_ok=True)
    ctx = load_context(work)
    only = {s for s in args.only.split(",") if s}
    up0 = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    rows = measure(ctx, figs, args.repeats, only)
    if not args.skip_fresh:
        measure_fresh(work, rows)
    from common import machine_info, machine_text

    info = machine_info()
    stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    cmd = "MPLBACKEND=Agg .venv/bin/python bench/bench_arviz_plots.py " + " ".join(sys.argv[1:])
    print(f"`{cmd}` - {stamp}\n\n{machine_text(info)} `uptime` at the start: {up0}. "
          f"arviz-plots {__import__('arviz_plots').__version__}, matplotlib {__import__('matplotlib').__version__}."
          f"\n\n{table(rows)}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=str))


if __name__ == "__main__":
    main()
