"""The corner plot of a fit's posterior draws (:func:`plot_pair`)."""

import re

import matplotlib.ticker
import numpy as np
from matplotlib.figure import Figure

from skinfit.plots.reading import param_label, sampled_slots, slot_values, use_log
from skinfit.plots.style import (
    COLOURS,
    MAP_COLOUR,
    MAX_WIDTH,
    MIN_FONT,
    finish_figure,
    log_ticks,
    plain_scale,
    suptitle,
    tick_text,
)
from skinfit.results.fit import as_fit

__all__ = ["plot_pair"]

_MAX_PAIR = 10  # parameters drawn by default


def plot_pair(fit, path=None, *, var_names=None, max_draws=1500):
    """Corner plot: marginals on the diagonal, pairwise draws below, the MAP marked.

    Positive parameters on log axes (their sampling coordinate). By default every sampled
    scalar when there are at most 10, else the parameters not split by a column.
    """
    fit = as_fit(fit)
    slots = sampled_slots(fit)
    if var_names is not None:
        slots = [s for s in slots if s["name"] in var_names or s["base"] in var_names]
    elif len(slots) > _MAX_PAIR:
        slots = [s for s in slots if s["level"] is None][:_MAX_PAIR]
    ds = fit.group("posterior")
    values = np.column_stack([slot_values(ds, s).ravel() for s in slots])
    if len(values) > max_draws:
        values = values[np.linspace(0, len(values) - 1, max_draws).astype(int)]
    # plain numbers on every axis: each parameter in its unit with an SI prefix or a power of ten
    scales = [plain_scale(values[:, k], s["unit"], s["display"]) for k, s in enumerate(slots)]
    values = values / np.array([f for f, _ in scales])
    mapv = {s["name"]: fit.map[s["name"]] / f for s, (f, _) in zip(slots, scales)}
    d = len(slots)
    size = min(1.6 * d + 1.4, MAX_WIDTH)
    fig = Figure(figsize=(size, size))  # a fixed layout: constrained layout is slow on d*d axes
    # labels as "name\n[unit]"; with more than 5 parameters a cell is too small for a label
    # along its side: y labels written across, margins to fit them
    compact = d > 5
    cell_chars = int((size - 1.2) / d * 72 / (0.6 * MIN_FONT))  # a column's width in characters, roughly
    labels = [_broken(param_label(s["name"], shown).replace(" [", "\n["), cell_chars)
              for s, (_, shown) in zip(slots, scales)]
    chars = max(_visible_length(line) for text in labels for line in text.split("\n"))
    two_lines = max(t.count("\n") + 1 for t in labels) * 1.3 * MIN_FONT / 72 + 0.1
    left_in = chars * 0.6 * MIN_FONT / 72 + 0.15 if compact else two_lines
    # x labels stay level under the upright tick labels (turned upright too they ran into them)
    fig.subplots_adjust(left=(0.55 + left_in) / size, bottom=(0.7 + two_lines) / size, right=1 - 0.15 / size,
                        top=1 - 0.6 / size, wspace=0.1, hspace=0.1)
    gs = fig.add_gridspec(d, d)
    log = [use_log(s, values[:, k]) for k, s in enumerate(slots)]
    axes = np.full((d, d), None, dtype=object)
    for i in range(d):
        for j in range(i + 1):
            ax = axes[i, j] = fig.add_subplot(gs[i, j])
            si, sj = slots[i], slots[j]
            if i == j:
                v = values[:, i]
                counts, edges = np.histogram(v, bins=np.geomspace(v.min(), v.max(), 40) if log[i] else 40)
                ax.stairs(counts, edges, fill=True, color=COLOURS[0], alpha=0.7)  # one patch, not 40 bars
                ax.axvline(mapv[si["name"]], color=MAP_COLOUR, lw=1)
                if log[i]:
                    ax.set_xscale("log")
            else:
                ax.scatter(values[:, j], values[:, i], s=1.5, alpha=0.25, color=COLOURS[0], lw=0,
                           rasterized=True)
                ax.plot(mapv[sj["name"]], mapv[si["name"]], marker="x", color=MAP_COLOUR, ms=5)
                if log[j]:
                    ax.set_xscale("log")
                if log[i]:
                    ax.set_yscale("log")
            if i == d - 1:
                ax.set_xlabel(labels[j], fontsize=MIN_FONT)
            else:
                ax.tick_params(labelbottom=False)
            if j == 0 and i > 0:
                if compact:
                    ax.set_ylabel(labels[i], fontsize=MIN_FONT, rotation=0, ha="right", va="center")
                else:
                    ax.set_ylabel(labels[i], fontsize=MIN_FONT)
            else:
                ax.tick_params(labelleft=False)
            ax.minorticks_off()
            ax.tick_params(labelsize=MIN_FONT)
            ax.tick_params(axis="x", labelrotation=90)  # upright: never into the next column's
            for axis in (ax.xaxis, ax.yaxis):
                if axis.get_scale() != "log":  # no label at a cell's edge, where it would meet the next
                    axis.set_major_locator(matplotlib.ticker.MaxNLocator(3, prune="both"))
                    axis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: tick_text(v)))
            if i == j:
                ax.set_yticks([])
    for j in range(d):  # the x range of each column is its marginal's
        for i in range(j + 1, d):
            axes[i, j].set_xlim(axes[j, j].get_xlim())
    for i in range(1, d):
        for j in range(i):
            axes[i, j].set_ylim(axes[i, i].get_xlim())
    for i in range(d):
        for j in range(i + 1):
            for which in "xy":
                if (axes[i, j].get_xscale() if which == "x" else axes[i, j].get_yscale()) == "log":
                    log_ticks(axes[i, j], which, 3, sparse=True)
    suptitle(fig, f"{fit.model_id} on {fit.dataset_id}: posterior draws (MAP in orange-red)")
    return finish_figure(fig, path)


def _broken(label, width):
    """``label`` ("name\\n[unit]") with lines longer than ``width`` characters broken, so that an
    x label stays within its column: the name after an underscore (``sigma_contact_area`` ->
    ``sigma_contact_`` / ``area``), the unit after its power of ten (``[10⁻⁶`` / ``m^2/N^m]``;
    never inside a unit such as ``N^n_z``)."""
    name, *rest = label.split("\n")
    lines, current = [], ""
    parts = name.split("_")
    for k, part in enumerate(parts):
        piece = part + ("_" if k < len(parts) - 1 else "")
        if current and len(current) + len(piece) > width:
            lines.append(current)
            current = ""
        current += piece
    rest = [_break_unit(u) if _visible_length(u) > width else u for u in rest]  # "[10⁻⁶" over "m²/Nᵐ]"
    return "\n".join([*lines, current, *rest])


def _break_unit(unit):
    """``[10⁻⁶ m²/Nᵐ]`` -> ``[10⁻⁶`` / ``m²/Nᵐ]``: at the first space outside a mathtext span
    (``$...$`` cut in two is drawn as its source); unchanged when there is none."""
    depth = 0
    for i, ch in enumerate(unit):
        if ch == "$":
            depth ^= 1
        elif ch == " " and not depth:
            return unit[:i] + "\n" + unit[i + 1:]
    return unit


def _visible_length(line):
    """Characters ``line`` shows: a mathtext span counted by what it draws (``$\\mathrm{N}^{n_{z}}$``
    as ``Nnz``), not by its source, which would widen the margins it sets."""
    def drawn(m):
        return re.sub(r"\\[A-Za-z]+|[{}^_ ]", "", m.group(0)[1:-1].replace("\\cdot", "*"))

    return len(re.sub(r"\$[^$]*\$", drawn, line))
