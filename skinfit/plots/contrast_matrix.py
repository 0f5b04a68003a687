"""Contrasts between many subjects as a matrix: one cell per pair, coloured by the size of the
effect, marked where its direction is near certain (a table of hundreds of pairs is read here
at a glance)."""

import numpy as np

from skinfit.plots.style import MIN_FONT, finish_figure, new_figure

__all__ = ["plot_contrast_matrix"]


def _pair_values(table, order=None):
    """(labels, matrix of effect sizes, matrix of probabilities of direction) of one
    parameter's contrasts: the log ratio (ratios) or the difference over its sd, signed A
    against B, in cell (A, B) and with the opposite sign in (B, A)."""
    found = set(table["A"]) | set(table["B"])
    labels = [x for x in (order or []) if x in found]
    labels += [x for x in dict.fromkeys([*table["A"], *table["B"]]) if x not in labels]
    index = {label: i for i, label in enumerate(labels)}
    n = len(labels)
    size, pd_ = np.full((n, n), np.nan), np.full((n, n), np.nan)
    for row in table.itertuples(index=False):
        if row.effect == "ratio":
            value = np.log(row.estimate)
        else:
            value = row.estimate / row.sd if row.sd > 0 else 0.0
        i, j = index[row.A], index[row.B]
        size[i, j], size[j, i] = value, -value
        pd_[i, j] = pd_[j, i] = row.prob_direction
    return labels, size, pd_


def plot_contrast_matrix(table, parameter, path=None, *, strong=0.95, order=None):
    """The pairwise contrasts of ``parameter`` (rows of a table of
    :func:`skinfit.analysis.contrasts.fit_contrasts` with a ``parameter`` column, or all its
    rows) as a matrix: cell (row A, column B) coloured by the effect of A against B (log of
    the ratio A / B for a positive parameter, else the difference over its posterior sd),
    a dot where the probability of direction exceeds ``strong``; a colour bar names the scale.
    ``order``: the subjects' (levels') order on both axes (default: as the pairs name them)."""
    t = table[table["parameter"] == parameter] if "parameter" in table.columns else table
    labels, size, pd_ = _pair_values(t, order)
    n = len(labels)
    ratio = bool((t["effect"] == "ratio").all())
    side = min(9.0, max(4.0, 0.32 * n + 2.2))
    fig = new_figure(side + 1.4, side)
    ax = fig.add_subplot()
    limit = float(np.nanmax(np.abs(size))) if np.isfinite(size).any() else 1.0
    image = ax.imshow(size, cmap="RdBu_r", vmin=-limit, vmax=limit)
    rows, cols = np.nonzero(pd_ > strong)
    ax.plot(cols, rows, "o", color="black", ms=max(2.0, 6.0 - 0.1 * n), linestyle="none")
    ax.set_xticks(range(n), labels, rotation=90, fontsize=MIN_FONT)
    ax.set_yticks(range(n), labels, fontsize=MIN_FONT)
    ax.set_xlabel("B")
    ax.set_ylabel("A")
    bar = fig.colorbar(image, ax=ax, shrink=0.8)
    bar.set_label("log(A / B)" if ratio else "(A − B) / sd")
    ax.set_title(f"{parameter}: {len(t)} pairwise contrasts; dots: P(direction) > {strong:g}",
                 fontsize=MIN_FONT + 1)
    return finish_figure(fig, path)
