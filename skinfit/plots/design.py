"""The expected information gain of one measurement over the candidates of a design
(:func:`skinfit.analysis.design.design`)."""

import numpy as np

from skinfit.plots.style import finish_figure, new_figure

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
    ax.set_ylabel("expected information gain of one measurement [nats]")
    ax.set_title(f"{result.model_id}: targets {', '.join(result.settings['params'])}; circles = plan "
                 f"(size = repeats)", fontsize=9)
    if len(groups) > 1:
        ax.legend(fontsize=7)
    return finish_figure(fig, path)
