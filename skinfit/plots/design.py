"""The expected information gain of one measurement over the candidates of a design
(:func:`skinfit.analysis.design.design`)."""

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from skinfit.plots.style import MIN_FONT, finish_figure, new_figure, wrap_title

__all__ = ["plot_eig"]


def plot_eig(result, path=None):
    """EIG of one measurement (nats, with +-2 MC standard errors) against the model's natural x
    axis (the card's ``[plot] x``, else the first covariate), one line per value of the other
    covariates (at most 8 shown); the plan's points marked with how often each is used."""
    t = result.table
    xname = result.plot.get("x")
    fig = new_figure(6.4, 4.0)
    ax = fig.add_subplot()
    xcol = f"{xname} [{result.units[xname]}]" if xname else None
    others = [c for c in t.columns if c.endswith("]") and c != xcol]
    groups = list(t.groupby(others, sort=True)) if others else [((), t)]
    if len(groups) > 8:
        keep = np.unique(np.linspace(0, len(groups) - 1, 8).round().astype(int))
        groups = [groups[i] for i in keep]
    for key, g in groups:
        key = key if isinstance(key, tuple) else (key,)
        label = ", ".join(f"{c.split(' [')[0]} {v:g} {c.split('[')[1][:-1]}" for c, v in zip(others, key)) or None
        x = g[xcol].to_numpy() if xcol else np.arange(len(g))
        order = np.argsort(x, kind="stable")
        x, e, se = x[order], g["eig"].to_numpy()[order], g["eig_se"].to_numpy()[order]
        line, = ax.plot(x, e, marker=".", label=label)
        ax.fill_between(x, e - 2 * se, e + 2 * se, color=line.get_color(), alpha=0.2, linewidth=0)
        used = g["in_plan"].to_numpy()[order] > 0
        ax.scatter(x[used], e[used], s=30 + 20 * g["in_plan"].to_numpy()[order][used], facecolors="none",
                   edgecolors="k", zorder=3)
    if result.plot.get("xscale") == "log":
        ax.set_xscale("log")
    ax.set_xlabel(xcol or "candidate")
    ax.set_ylabel("expected information gain\nof one measurement [nats]")  # two lines: one was cut at 4 in
    ax.set_title(wrap_title(f"{result.model_id}: targets {', '.join(result.settings['params'])}", ax), fontsize=9)
    handles, _ = ax.get_legend_handles_labels()
    handles.append(Line2D([], [], ls="none", marker="o", mfc="none", mec="k", ms=7,
                          label="in the plan (size: repeats)"))
    handles.append(Patch(color="0.5", alpha=0.3, lw=0, label="\u00b12 Monte Carlo standard errors"))
    fig.legend(handles=handles, fontsize=MIN_FONT, frameon=False, loc="outside lower center",
               ncols=min(len(handles), 3))
    return finish_figure(fig, path)
