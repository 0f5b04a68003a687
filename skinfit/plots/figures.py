"""Figures for papers, drawn from saved results only (a :class:`~skinfit.Fit` or its DataTree).

Posterior-predictive plots in each model's natural axes (:func:`plot_ppc`): the data over the
50% and 90% posterior-predictive bands and the posterior median curve, one panel per condition,
axes in the units the data came in. Inference plots: :func:`plot_pair` (corner),
:func:`plot_trace` (walker traces with rank histograms), :func:`plot_rank` (ArviZ),
:func:`plot_prior_posterior` (what the data determined), :func:`plot_forest` (a parameter
across subjects and conditions, with the population distribution when given) and
:func:`plot_comparison` (evidence / LOO chart).

Every function returns a :class:`matplotlib.figure.Figure` and writes it to ``path`` when one
is given. Figures are made without pyplot (nothing is ever shown); where ArviZ is used, the
Agg backend is selected unless the user already chose one (``MPLBACKEND`` or an explicit
``matplotlib.use``).

Panels and colours come from the model card's optional ``[plot]`` table::

    [plot]
    x = "normal_force"          # covariate on the x axis (default: the first covariate)
    panels = ["voltage"]        # one panel per level (combination) of these columns
    colours = ["material"]      # optional: one colour per level within a panel
    xscale = "linear"           # or "log"; yscale likewise
    yscale = "linear"
    reference = "ball_bearing"  # optional reference curve (default: when the data allow it)
    pair = ["impedance", "contact_area"]   # two observables: x, y of the extra row

Without a ``[plot]`` table, panels are the columns of the data (other than x) with 2-12 levels.
A numeric panel column with more than 12 distinct values is cut into three ranges (e.g. load
ranges).
"""

import math
import os
import re
import tomllib
import warnings
from pathlib import Path

import matplotlib
import matplotlib.artist
import matplotlib.colors
import matplotlib.layout_engine
import matplotlib.lines
import matplotlib.ticker
import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from skinfit.errors import InputError
from skinfit.results.fit import as_fit
from skinfit.io.units import to_si

__all__ = ["plot_ppc", "ppc_bands", "plot_spec", "plot_pair", "plot_trace", "plot_rank",
           "plot_prior_posterior", "plot_forest", "plot_comparison", "parameter_units", "axis_label"]

#: Central posterior-predictive bands drawn by :func:`plot_ppc` and returned by :func:`ppc_bands`.
QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)
_BAND_COLUMNS = ("q05", "q25", "q50", "q75", "q95")
_MAX_PANELS = 12
_MAX_PANELS_MULTI = 6
_MAX_LEVELS = 12  # a numeric panel column with more distinct values is cut into ranges
_N_CURVE_DRAWS = 100  # the median curve of 100 draws: no visible change from 300, a third of the cost
_N_GRID = 160
#: A median marked at the data's x, where no curve may join the data's points: a short bar
#: (the other levels' medians, thin and grey, as a plain one).
_MEDIAN_MARK = {"ls": "", "marker": "_", "ms": 10, "mew": 2}
_OTHER_MARK = {"ls": "", "marker": "_"}
_MAX_PAIR = 10
#: Okabe & Ito's colour-blind-safe palette (Color Universal Design, 2008; yellow left out: too
#: pale on white), then two darker greys.
_COLOURS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000", "#666666")
_MAP_COLOUR = "#D55E00"
_DPI = 120
#: Widest figure [in]: the report shows figures at their pixel size up to its 1136 px column
#: (1200 px less padding), so 8 pt text stays >= 8 pt (13 px at 120 dpi) as displayed.
MAX_WIDTH = 9.4
#: Smallest font size [pt] of any text in a figure.
MIN_FONT = 8


def _ensure_backend():
    """Agg unless the user chose a backend (MPLBACKEND or matplotlib.use); for ArviZ's pyplot."""
    chosen = getattr(matplotlib.rcParams, "_get_backend_or_none", lambda: "unknown")()
    if os.environ.get("MPLBACKEND") is None and chosen is None:
        matplotlib.use("Agg")


# ---- reading a saved fit ------------------------------------------------------------------
def _card(fit):
    return tomllib.loads(fit.attrs["model_card"])


def _data_units(fit):
    """Column -> unit the data came in (dataset card), falling back to the model card's SI unit."""
    card = _card(fit)
    units = {q["name"]: q["unit"] for key in ("observables", "covariates") for q in card.get(key, [])}
    units.update(fit.attr("data_units") if "data_units" in fit.attrs else fit.attr("units"))
    return units


def _factor(unit):
    """Factor from SI to ``unit`` (divide SI values by it); 1 for units skinfit does not convert."""
    try:
        return to_si(unit)
    except ValueError:  # a symbolic model unit such as N^n_z
        return 1.0


def axis_label(name, unit=None):
    """``"normal_force", "mN"`` -> ``"normal force [mN]"``; dimensionless -> ``[-]``."""
    text = name.replace("_", " ")
    return text if unit is None else f"{text} [{_unit_text(unit)}]"


def _unit_text(unit):
    return "-" if unit in ("1", "-", "") else unit


def parameter_units(fit):
    """Parameter (or noise parameter) name -> SI unit as stated in the model card."""
    from skinfit.io.labels import parameter_units as units

    return units(as_fit(fit))


def _slots(fit, densities=False):
    """The sampled scalars: name, base, level, unit, whether plotted on a log axis (a prior
    bounded below by 0) and, for a plot of the priors' ``densities``, the prior, checked against
    scipy.stats; the other plots read the bounds alone and do not import it (~0.5 s of a figure
    worker's first figure)."""
    from skinfit.results.summary import priors_from_attrs

    priors = priors_from_attrs(fit.attrs, check_mass=densities)
    units = parameter_units(fit)
    out = []
    for s in fit.attr("slots"):
        prior = priors.get(s["base"])
        out.append({**s, "unit": units.get(s["base"]), "prior": prior if densities else None,
                    "log": prior is not None and prior.lower >= 0})
    return out


def _use_log(slot, values):
    """Log axis for a positive parameter whose values span more than a factor of 10."""
    values = np.asarray(values, dtype=float)
    return bool(slot["log"] and values.min() > 0 and values.max() > 10 * values.min())


class _InView(matplotlib.ticker.Locator):
    """The ticks of ``base`` that lie in the axis' view: the same marks, but no tick objects made,
    placed and formatted at every draw for the positions outside it (a log axis' locators
    return whole decades beyond both ends)."""

    def __init__(self, base):
        self.base = base

    def set_axis(self, axis):
        super().set_axis(axis)
        self.base.set_axis(axis)

    def __call__(self):
        lo, hi = sorted(self.axis.get_view_interval())
        ticks = np.asarray(self.base(), dtype=float)
        slack = 1e-9 * (hi - lo)  # a tick at an end, to rounding, is drawn: keep it
        return ticks[(ticks >= lo - slack) & (ticks <= hi + slack)]

    def tick_values(self, vmin, vmax):
        return self.base.tick_values(vmin, vmax)

    def nonsingular(self, v0, v1):  # autoscaling asks the major locator (a log one keeps v0 > 0)
        return self.base.nonsingular(v0, v1)

    def view_limits(self, vmin, vmax):
        return self.base.view_limits(vmin, vmax)


class _MinorMarks(matplotlib.artist.Artist):
    """The minor tick marks of one axes' x or y axis, drawn as one line of tick markers placed
    at each draw at the positions ``locator`` gives in view, less those at a major tick: the
    marks matplotlib's minor ticks draw (marker, length, width, colour and direction from
    rcParams), without a Tick of five artists per mark made, placed and laid out at every draw
    (a 21-panel predictive check had ~120: 13% of its drawing time, bench/results/report_commands.md).
    Left out of the layout: a mark is shorter than the major ticks beside it."""

    _MARKERS = {("x", "out"): matplotlib.lines.TICKDOWN, ("x", "in"): matplotlib.lines.TICKUP,
                ("x", "inout"): "|", ("y", "out"): matplotlib.lines.TICKLEFT,
                ("y", "in"): matplotlib.lines.TICKRIGHT, ("y", "inout"): "_"}

    def __init__(self, ax, which, locator):
        super().__init__()
        rc = matplotlib.rcParams
        direction = rc[f"{which}tick.direction"]
        self.which, self.locator = which, locator
        self._in_view = _InView(locator)
        self._in_view.set_axis(ax.xaxis if which == "x" else ax.yaxis)
        self._line = Line2D([], [], linestyle="none", marker=self._MARKERS[which, direction],
                            markersize=rc[f"{which}tick.minor.size"] * (2 if direction == "inout" else 1),
                            markeredgewidth=rc[f"{which}tick.minor.width"], color=rc[f"{which}tick.color"],
                            transform=ax.get_xaxis_transform() if which == "x" else ax.get_yaxis_transform(),
                            clip_on=False)
        self._line.set_figure(ax.figure)
        self.set_zorder(ax.xaxis.get_zorder() if which == "x" else ax.yaxis.get_zorder())
        self.set_in_layout(False)
        ax.add_artist(self)

    @classmethod
    def of(cls, ax, which):
        """The marks of ``ax``'s ``which`` axis, or None."""
        return next((a for a in ax.artists if isinstance(a, cls) and a.which == which), None)

    def positions(self):
        """The marks' positions in data units: in view (:class:`_InView`), none at a major tick
        (as :meth:`matplotlib.axis.Axis.get_minorticklocs` drops them)."""
        axis = self.axes.xaxis if self.which == "x" else self.axes.yaxis
        locs = np.asarray(self._in_view(), dtype=float)
        transform = axis.get_transform()
        t_lo, t_hi = sorted(transform.transform(axis.get_view_interval()))
        t_locs, t_major = transform.transform(locs), transform.transform(np.asarray(axis.get_majorticklocs()))
        return locs[~np.isclose(t_locs[:, None], t_major[None, :], atol=(t_hi - t_lo) * 1e-5, rtol=0).any(axis=1)]

    def draw(self, renderer):
        if not self.get_visible():
            return
        locs = self.positions()
        zeros = np.zeros_like(locs)  # on the bottom or left spine (axes coordinates)
        self._line.set_data((locs, zeros) if self.which == "x" else (zeros, locs))
        self._line.draw(renderer)


def _log_ticks(ax, which="x", numticks=5, sparse=False):
    """Readable ticks on a log axis (call after its limits are set): decades, or 1, 2, 5 x 10^k
    on a range of less than 1.5 decades (``sparse``: at most ``numticks`` evenly spaced values
    away from the ends, for small panels), labelled as plain numbers; unlabelled minor marks
    (:class:`_MinorMarks`) except between 1, 2, 5 x 10^k labels, where they add nothing to the
    labels and the grid. Only ticks in view are made (:class:`_InView`)."""
    axis = ax.xaxis if which == "x" else ax.yaxis
    lo, hi = ax.get_xlim() if which == "x" else ax.get_ylim()
    short = math.log10(hi / lo) < 1.5
    if short and sparse:
        axis.set_major_locator(matplotlib.ticker.MaxNLocator(numticks, prune="both"))
        axis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:.3g}"))
    else:
        axis.set_major_locator(_InView(matplotlib.ticker.LogLocator(
            subs=(1.0, 2.0, 5.0) if short else (1.0,), numticks=3 * numticks if short else numticks)))
        axis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    marks = _MinorMarks.of(ax, which)
    if short and not sparse:  # labelled 1, 2, 5 x 10^k: unlabelled marks between them add nothing
        if marks is not None:
            marks.remove()
    elif marks is None:
        locator = axis.get_minor_locator()
        if isinstance(locator, matplotlib.ticker.NullLocator):  # a shared axis: set by a sibling's marks
            shared = ax.get_shared_x_axes() if which == "x" else ax.get_shared_y_axes()
            siblings = [_MinorMarks.of(sibling, which) for sibling in shared.get_siblings(ax)]
            locator = next((m.locator for m in siblings if m is not None), None)
        if locator is not None:
            _MinorMarks(ax, which, locator)
    axis.set_minor_locator(matplotlib.ticker.NullLocator())  # the marks above stand for its minor ticks
    axis.set_minor_formatter(matplotlib.ticker.NullFormatter())


def _values(ds, slot):
    """(chain, draw) values of one slot from a posterior/prior Dataset."""
    da = ds[slot["base"]]
    if slot["level"] is not None:
        dim = [d for d in da.dims if d not in ("chain", "draw")][0]
        da = da.sel({dim: slot["level"]})
    return np.asarray(da.transpose("chain", "draw").values, dtype=float)


#: Fonts of a saved PDF or PostScript figure embedded as TrueType (Type 42) subsets, not as
#: matplotlib's default Type 3 fonts, which IEEE's and ScholarOne's manuscript checks refuse.
SAVE_RC = {"pdf.fonttype": 42, "ps.fonttype": 42}


def save_figure(fig, target, **kwargs):
    """``fig.savefig(target, **kwargs)`` with :data:`SAVE_RC` and, when it sets the text exactly
    as DejaVu Sans does, a cut of that font quicker to embed (:mod:`skinfit.plots._pdf_font`): what
    every saved figure goes through."""
    from skinfit.plots._pdf_font import rc_for

    with matplotlib.rc_context({**SAVE_RC, **rc_for(fig)}):
        fig.savefig(target, **kwargs)


def _finish(fig, path):
    if path is not None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        save_figure(fig, path, dpi=_DPI)
    return fig


def _fix_layout(fig):
    """Run the figure's layout engine once and keep its result (no engine left), so that the
    PNG and then the PDF are drawn without laying the figure out again. Minor ticks carry no
    labels and so do not move the layout: they are left out while it is measured (making and
    placing them in each of constrained layout's two passes was a third of a many-panel
    figure's drawing time)."""
    engine = fig.get_layout_engine()
    if engine is None or not fig.axes:
        return
    saved = []
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            if not axis.label.get_text():  # an empty label: put on the spine once, not placed by
                # measuring the tick labels again at each layout pass and draw
                axis.set_label_coords(*((0.5, 0) if axis is ax.xaxis else (0, 0.5)))
            saved.append((axis, axis.get_minor_locator(), axis.isDefault_minloc))
            axis.set_minor_locator(matplotlib.ticker.NullLocator())
    try:
        engine.execute(fig)
    finally:
        for axis, locator, default in reversed(saved):  # shared axes share one locator
            axis.set_minor_locator(locator)
            axis.isDefault_minloc = default
    fig.set_layout_engine(None)


def _new_figure(width, height):
    return Figure(figsize=(min(width, MAX_WIDTH), height), layout="constrained")


def _suptitle(fig, text, fontsize=10):
    """A figure title wrapped at word boundaries (also after ``:`` and ``[``) to the figure's
    width, so that a long model or dataset name is never cut at the canvas edge."""
    import textwrap

    per_line = max(20, int(fig.get_figwidth() * 72 / (0.6 * fontsize)))  # ~0.6 em per character
    spaced = text.replace("[", " [").replace(",", ", ").replace(",  ", ", ")
    lines = textwrap.wrap(spaced, per_line, break_long_words=True, break_on_hyphens=False)
    return fig.suptitle("\n".join(lines).replace(" [", "["), fontsize=fontsize)


# ---- posterior-predictive plots -----------------------------------------------------------
def plot_spec(fit):
    """What :func:`plot_ppc` draws: x column, panel and colour columns, scales, reference.

    Read from the model card's ``[plot]`` table, with defaults from the data.
    """
    fit = as_fit(fit)
    card = _card(fit)
    table = dict(card.get("plot", {}))
    cd = fit.group("constant_data")
    observables = list(fit.group("observed_data").data_vars)
    covariates = [c["name"] for c in card.get("covariates", [])]
    x = table.get("x") or next((c for c in covariates if c in cd), None)
    if x is None:
        x = next((c for c in cd.data_vars if np.issubdtype(cd[c].dtype, np.number)), None)
    if x is None or x not in cd:
        raise InputError(f"model card {fit.model_id}", f"plot.x: no column {x!r} in the saved data "
                         f"(columns: {', '.join(cd.data_vars)})", field="plot.x")

    def _columns(key):
        value = table.get(key)
        if value is None:
            return None
        value = [value] if isinstance(value, str) else list(value)
        return [c for c in value if c in cd and c != x]  # a column the data lack: nothing to split by

    panels = _columns("panels")
    colours = _columns("colours") or _columns("colors") or []
    if panels is None:
        ordered = covariates + [c for c in cd.data_vars if c not in covariates]
        panels = [c for c in ordered if c in cd and c != x and c not in colours
                  and 2 <= _n_levels(cd[c].values) <= _MAX_PANELS]
    limit = _MAX_PANELS if len(observables) == 1 else _MAX_PANELS_MULTI
    while len(panels) > 1 and _n_combinations(cd, panels) > limit:
        colours.insert(0, panels.pop())  # too many panels: the last panel column becomes colour
    if panels and _n_combinations(cd, panels) > limit and not colours:
        colours, panels = panels, []
    reference = table.get("reference")
    if reference is None and {"position", "amplitude", "wavelength"} <= set(cd.data_vars):
        reference = "ball_bearing"
    pair = table.get("pair")
    if pair is None and len(observables) == 2:
        pair = [observables[1], observables[0]]
    return {"x": x, "panels": panels, "colours": colours, "observables": observables,
            "xscale": table.get("xscale", "linear"), "yscale": table.get("yscale", "linear"),
            "reference": None if reference in (None, "none") else reference,
            "pair": list(pair) if pair else None}


def _n_levels(values):
    return len(pd.unique(pd.Series(values)))


def _n_combinations(cd, columns):
    return len(pd.DataFrame({c: cd[c].values for c in columns}).drop_duplicates())


def _levels(fit, column, units):
    """Codes (n,) and labels of a panel/colour column, in data units, NaN as 'none'."""
    values = fit.group("constant_data")[column].values
    unit = units.get(column)
    numeric = np.issubdtype(values.dtype, np.number)
    if not numeric:
        labels = sorted(pd.unique(pd.Series(values).astype(str)))
        codes = np.array([labels.index(str(v)) for v in values])
        return codes, [f"{column.replace('_', ' ')} = {lab}" for lab in labels]
    shown = values.astype(float) / _factor(unit) if unit else values.astype(float)
    suffix = "" if unit in (None, "1", "-") else f" {unit}"
    finite = np.unique(shown[np.isfinite(shown)])
    has_nan = bool(np.isnan(shown).any())
    name = column.replace("_", " ")
    if len(finite) > _MAX_LEVELS:  # a continuous column: three ranges of equal counts
        edges = np.quantile(shown[np.isfinite(shown)], [0, 1 / 3, 2 / 3, 1])
        inner = np.clip(np.searchsorted(edges[1:-1], shown, side="right"), 0, 2)
        codes = np.where(np.isnan(shown), 0, inner + (1 if has_nan else 0))
        labels = ([f"{name}: none"] if has_nan else []) + [
            f"{name} {edges[i]:.3g}–{edges[i + 1]:.3g}{suffix}" for i in range(3)]
        return codes, labels
    codes = np.searchsorted(finite, shown) + (1 if has_nan else 0)
    codes = np.where(np.isnan(shown), 0, codes)
    labels = ([f"{name} = none"] if has_nan else []) + [f"{name} = {v:g}{suffix}" for v in finite]
    return codes, labels


def _keys(fit, columns, units):
    """Combined level code per row and the label of each combination present."""
    n = fit.group("observed_data").sizes["obs_id"]
    if not columns:
        return np.zeros(n, dtype=int), [""]
    parts = [_levels(fit, c, units) for c in columns]
    combos = list(zip(*[codes for codes, _ in parts]))
    present = sorted(set(combos))
    index = {k: i for i, k in enumerate(present)}
    labels = [", ".join(parts[j][1][k[j]] for j in range(len(columns))) for k in present]
    return np.array([index[k] for k in combos]), labels


def _ppc_draws(fit, observable, max_draws=20000):
    arr = fit.group("posterior_predictive")[observable].transpose("chain", "draw", "obs_id").values
    arr = arr.reshape(-1, arr.shape[-1])
    if len(arr) > max_draws:
        arr = arr[np.linspace(0, len(arr) - 1, max_draws).astype(int)]
    return arr


def observable_floor(fit, observable):
    """Lower end of an observable's physical support in SI (0), or None when it may be negative.

    An observable is non-negative when its card unit has a non-negative dimension
    (:data:`skinfit.io.units.NONNEGATIVE`: forces, areas, impedances...) or it is a friction
    coefficient (Coulomb's ``F_t / F_n`` with both forces >= 0); signed ratios such as the wavy
    surface's ``force_ratio`` are left alone.
    """
    from skinfit.io.units import NONNEGATIVE, dimension

    card = _card(fit)
    unit = next((o.get("unit") for o in card.get("observables", []) if o.get("name") == observable), None)
    try:
        nonneg = unit is not None and dimension(unit) in NONNEGATIVE
    except KeyError:
        nonneg = False
    return 0.0 if nonneg or observable == "friction_coefficient" else None


def ppc_bands(fit):
    """Per observation: x, observed and the 5/25/50/75/95% posterior-predictive quantiles.

    Returns a long DataFrame with columns ``observable, obs_id, x, observed, q05, q25, q50,
    q75, q95, panel, colour`` (``panel``/``colour`` are level codes of :func:`plot_spec`'s
    columns, labels in ``df.attrs``); values in the units the data came in. The 50% band is
    [q25, q75], the 90% band [q05, q95]: the bands :func:`plot_ppc` draws.

    Quantiles of a non-negative observable (:func:`observable_floor`) are clipped at 0: a
    normal noise model puts some predictive draws below 0, which no measurement can be (the
    coverage of observed values >= 0 is unchanged). ``df.attrs["below_floor"]`` gives, per
    observable, the share of predictive draws that fell below it (0 for log-normal noise).
    """
    fit = as_fit(fit)
    spec = plot_spec(fit)
    units = _data_units(fit)
    cd = fit.group("constant_data")
    od = fit.group("observed_data")
    x = np.asarray(cd[spec["x"]].values, dtype=float) / _factor(units.get(spec["x"]))
    panel, panel_labels = _keys(fit, spec["panels"], units)
    colour, colour_labels = _keys(fit, spec["colours"], units)
    frames, below = [], {}
    for o in spec["observables"]:
        f = _factor(units.get(o))
        draws = _ppc_draws(fit, o)
        # np.quantile: the same numbers, vectorised (nanquantile goes column by column)
        q = (np.nanquantile if np.isnan(draws).any() else np.quantile)(draws, QUANTILES, axis=0)
        floor = observable_floor(fit, o)
        if floor is not None:
            below[o] = float(np.mean(draws < floor))
            q = np.maximum(q, floor)
        q = q / f
        frame = pd.DataFrame({"observable": o, "obs_id": od["obs_id"].values, "x": x,
                              "observed": od[o].values / f, "panel": panel, "colour": colour})
        for name, row in zip(_BAND_COLUMNS, q):
            frame[name] = row
        frames.append(frame)
    out = pd.concat(frames, ignore_index=True)
    out.attrs.update(panel_labels=panel_labels, colour_labels=colour_labels, spec=spec, below_floor=below)
    return out


def _theta_draws(fit, post, n):
    """(n, d) natural parameter vectors evenly spread over the posterior draws."""
    ds = fit.group("posterior")
    cols = [_values(ds, {"base": s.base, "level": s.level}).ravel() for s in post.slots]
    theta = np.column_stack(cols)
    if len(theta) > n:
        theta = theta[np.linspace(0, len(theta) - 1, n).astype(int)]
    return theta


def _median_curves(fit, spec, keys):
    """Posterior median of the noiseless prediction per (panel, colour) group.

    On a fine x grid when, within the group, every other covariate and every (split)
    parameter is constant; else at the observed x. Returns {group: (x_si, {obs: y_si})}.
    """
    post = fit.posterior
    theta = _theta_draws(fit, post, _N_CURVE_DRAWS)
    params = post.unpack(theta)
    x_name = spec["x"]
    curves = {}
    for key in sorted(set(keys)):
        idx = np.flatnonzero(keys == key)
        grid = x_name in post.x and np.ptp(post.x[x_name][idx]) > 0
        p_group = {}
        for name, arr in params.items():
            if arr.shape[1] == 1:
                p_group[name] = arr
            elif np.all(arr[:, idx] == arr[:, idx[:1]]):
                p_group[name] = arr[:, idx[:1]]
            else:
                grid = False
        for name, values in post.x.items():
            v = values[idx]
            if name != x_name and not np.all((v == v[0]) | (np.isnan(v) & np.isnan(v[0]))):
                grid = False
        if grid:
            lo, hi = np.nanmin(post.x[x_name][idx]), np.nanmax(post.x[x_name][idx])
            xs = np.geomspace(lo, hi, _N_GRID) if spec["xscale"] == "log" and lo > 0 else np.linspace(lo, hi, _N_GRID)
            cov = {name: (xs if name == x_name else np.full(_N_GRID, values[idx[0]]))
                   for name, values in post.x.items()}
            pred, ok = post.model.forward(p_group, cov, post.constants)
        else:
            order = idx[np.argsort(post.x[x_name][idx], kind="stable")] if x_name in post.x else idx
            xs = np.asarray(fit.group("constant_data")[x_name].values, dtype=float)[order]
            pred, ok = post.model.forward(params, post.x, post.constants)
            pred = {o: np.broadcast_to(v, (len(theta), post.n))[:, order] for o, v in pred.items()}
            ok = np.broadcast_to(ok, (len(theta), post.n))[:, order] if np.ndim(ok) == 2 else ok
        out = {}
        for o in spec["observables"]:
            y = np.array(np.broadcast_to(pred[o], (len(theta), len(xs))), dtype=float)
            y[~np.broadcast_to(ok, y.shape)] = np.nan
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN column: outside support
                out[o] = np.nanmedian(y, axis=0)
            if not grid:  # replicates at one x (or other covariates varying): their mean
                out[o] = pd.Series(out[o]).groupby(xs).mean().to_numpy()
        curves[key] = (xs if grid else np.unique(xs), out, grid)
    return curves


def _ppc_median_curves(fit, bands, keys):
    """Fallback of :func:`_median_curves`: the posterior-predictive median at the observed x."""
    units = _data_units(fit)
    spec = bands.attrs["spec"]
    fx = _factor(units.get(spec["x"]))
    curves = {}
    for key in sorted(set(keys)):
        idx = np.flatnonzero(keys == key)
        out, xs = {}, None
        for o in spec["observables"]:
            rows = bands[bands["observable"] == o].iloc[idx]
            med = rows.groupby("x")["q50"].mean() * _factor(units.get(o))
            xs, out[o] = med.index.to_numpy() * fx, med.to_numpy()
        curves[key] = (xs, out, False)
    return curves


def _reference(spec, fit, idx, xs_si):
    """Reference curve in SI on ``xs_si`` for the rows ``idx``, or None."""
    if spec["reference"] != "ball_bearing":
        return None
    cd = fit.group("constant_data")
    a = np.asarray(cd["amplitude"].values, dtype=float)[idx]
    lam = np.asarray(cd["wavelength"].values, dtype=float)[idx]
    if not (np.all(a == a[0]) and np.all(lam == lam[0])):
        return None
    k = 2 * math.pi / lam[0]
    return -a[0] * k * np.sin(k * xs_si)  # docs/models/wavy_surface.md, eq. 2: ratio = g(x)


def _grid(fig, nrows, ncols, n_panels, multi, n_obs, transpose=False):
    """Axes as rows[r][panel]: multi = one row per observable (+ pair row), y shared per row,
    x shared down a column (``transpose``: the same axes laid out one panel per row, one
    observable per column, x shared by every panel of the observables and by every pair
    panel, so that only the bottom row needs x labels); otherwise one row of ``n_panels``
    wrapped, all axes shared."""
    if not multi:
        axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True, sharey=True).ravel()
        for ax in axes[n_panels:]:
            ax.set_visible(False)
        return [list(axes[:n_panels])]
    gs = fig.add_gridspec(ncols, nrows) if transpose else fig.add_gridspec(nrows, ncols)
    rows = []
    for r in range(nrows):
        row = []
        for c in range(ncols):
            if transpose:  # the covariate's panels with the first of them, the pair panels with theirs
                sharex = (row[0] if c else None) if r in (0, n_obs) else rows[0][0]
            else:
                sharex = rows[0][c] if 0 < r < n_obs else None
            row.append(fig.add_subplot(gs[c, r] if transpose else gs[r, c], sharex=sharex,
                                       sharey=row[0] if c else None))
        rows.append(row)
    return rows


def _bands_overlap(bands, observable, panel, n_colours, share=0.5):
    """True when, in some panel, two colour levels' 90% bands overlap over more than ``share``
    of the narrower band at the x values they share (then each level gets a panel)."""
    sub = bands[bands["observable"] == observable]
    for p in np.unique(panel):
        agg = {c: sub[(sub["panel"] == p) & (sub["colour"] == c)].groupby("x")[["q05", "q95"]].mean()
               for c in range(n_colours)}
        for a in range(n_colours):
            for b in range(a + 1, n_colours):
                common = agg[a].index.intersection(agg[b].index)
                if not len(common):
                    continue
                lo = np.maximum(agg[a].loc[common, "q05"], agg[b].loc[common, "q05"])
                hi = np.minimum(agg[a].loc[common, "q95"], agg[b].loc[common, "q95"])
                narrow = np.minimum(agg[a].loc[common, "q95"] - agg[a].loc[common, "q05"],
                                    agg[b].loc[common, "q95"] - agg[b].loc[common, "q05"])
                if np.mean(np.clip(hi - lo, 0, None) / np.where(narrow > 0, narrow, np.inf)) > share:
                    return True
    return False


def plot_ppc(fit, path=None):
    """Posterior-predictive plot in the model's natural axes.

    Per panel (a level of the card's ``plot.panels`` columns): the data, the 50% and 90%
    posterior-predictive bands (per observation: quantiles of the ``posterior_predictive``
    draws, clipped at 0 for a non-negative observable, see :func:`ppc_bands`) and the
    posterior median of the noiseless prediction, a curve on a fine grid of x when nothing
    else varies within the panel, else markers at the observed x; for models with two
    observables, one row per observable plus a row of one observable against the other;
    the wavy-surface ball-bearing curve (eq. 2) for reference when the data allow it.
    Levels of a colour column get one colour each (Okabe-Ito or viridis) and, when their bands
    overlap, one panel each (up to 12 panels; for two observables a row or column each). Axes are in the units the data came in.

    Returns the matplotlib Figure (written to ``path`` when given).
    """
    fit = as_fit(fit)
    bands = ppc_bands(fit)
    spec = bands.attrs["spec"]
    units = _data_units(fit)
    panel_labels, colour_labels = bands.attrs["panel_labels"], bands.attrs["colour_labels"]
    observables = spec["observables"]
    first = bands[bands["observable"] == observables[0]]
    panel = first["panel"].to_numpy()
    colour = first["colour"].to_numpy()
    n_colours = len(colour_labels)
    pair = spec["pair"] if spec["pair"] and all(p in observables for p in spec["pair"]) else None
    keys = panel * n_colours + colour
    fallback = False  # the model's noiseless median not computable here: the predictive one instead
    try:
        curves = _median_curves(fit, spec, keys)
    except InputError as exc:  # the saved card's forward function is not available, or its posterior not rebuilt
        curves, fallback = _ppc_median_curves(fit, bands, keys), True
        warnings.warn(f"{fit.model_id} on {fit.dataset_id}: the predictive check shows the predictive "
                      f"median at the data's x, not the model's noiseless curve: {exc}", stacklevel=2)

    multi = len(observables) > 1 or pair is not None
    multi_colour = n_colours > 1
    palette = _palette(fit, spec["colours"], n_colours)
    # overlapping bands of several colour levels (of any observable): one panel per (panel,
    # colour) level instead, when that makes at most _MAX_PANELS panels
    cells = [(p, c) for p in range(len(panel_labels)) for c in range(n_colours) if np.any((panel == p) & (colour == c))]
    split = (multi_colour and len(cells) <= _MAX_PANELS
             and any(_bands_overlap(bands, o, panel, n_colours) for o in observables))
    if not split:
        cells = [(p, None) for p in range(len(panel_labels))]
    n_panels = len(cells)
    transpose = False
    if multi:  # one row per observable (+ the pair row), one column per panel
        ncols, nrows = n_panels, len(observables) + (1 if pair else 0)
        transpose = n_panels > 3  # many panels: one per row instead, the observables across
    else:  # one observable: panels wrapped into a near-square grid
        ncols = min(4, math.ceil(math.sqrt(n_panels)))
        nrows = math.ceil(n_panels / ncols)
    gcols, grows = (nrows, ncols) if transpose else (ncols, nrows)  # as laid out
    width = min(2.9 * gcols + 0.8, MAX_WIDTH)
    title_lines = 2 if split and len(panel_labels) > 1 else 1
    n_handles = 6 + (n_colours if multi_colour else 0)
    x_labels = 0.35  # x tick labels and the x label under a row: the bottom row's alone when transposed
    fig = _new_figure(width, (0.7 * (width - 0.8) / gcols + 0.1 + 0.17 * title_lines) * grows
                      + x_labels * (1 if transpose else grows) + 0.2 * math.ceil(n_handles / 3) + 0.6)
    rows = _grid(fig, nrows, ncols, n_panels, multi, len(observables), transpose)
    for ax in fig.axes:  # limits once, from all the data, below: not again after every artist
        ax.set_autoscale_on(False)  # (each would autoscale all the axes it shares limits with)
    x_label = axis_label(spec["x"], units.get(spec["x"]))
    x_factor = _factor(units.get(spec["x"]))
    reference_drawn = markers_drawn = curve_drawn = False
    for r, o in enumerate(observables):
        f = _factor(units.get(o))
        sub = bands[bands["observable"] == o]
        for k, (p, only) in enumerate(cells):
            ax = rows[r][k]
            if ax.get_xscale() != spec["xscale"]:  # first: a scale set after the artists autoscales them
                ax.set_xscale(spec["xscale"])  # again; once: a shared axis sets it on all its siblings
            if ax.get_yscale() != spec["yscale"]:
                ax.set_yscale(spec["yscale"])
            for c in range(n_colours) if only is None else [only]:
                rows_pc = sub[(sub["panel"] == p) & (sub["colour"] == c)]
                if rows_pc.empty:
                    continue
                col = palette[c]
                agg = rows_pc.groupby("x", sort=True)[list(_BAND_COLUMNS)].mean()
                xu = agg.index.to_numpy()
                if len(xu) > 1:
                    ax.fill_between(xu, agg["q05"], agg["q95"], color=col, alpha=0.16, lw=0, gid="band90")
                    ax.fill_between(xu, agg["q25"], agg["q75"], color=col, alpha=0.34, lw=0, gid="band50")
                else:
                    ax.errorbar(xu, agg["q50"], yerr=[agg["q50"] - agg["q05"], agg["q95"] - agg["q50"]],
                                color=col, alpha=0.5, lw=3, capsize=0)
                ax.scatter(rows_pc["x"], rows_pc["observed"], s=12, color=col, edgecolor="black",
                           linewidth=0.4, zorder=3, gid="data")
                xs, ys, on_grid = curves[p * n_colours + c]
                if on_grid:
                    ax.plot(xs / x_factor, ys[o] / f, color=col, lw=1.6, zorder=4, gid="median")
                    curve_drawn = True
                else:  # other covariates vary within the panel: no curve through the data's x
                    ax.plot(xs / x_factor, ys[o] / f, color=col, zorder=4, gid="median", **_MEDIAN_MARK)
                    markers_drawn = True
            if split:  # the other levels' medians, thin and grey, for comparison
                for c in range(n_colours):
                    if c != only and p * n_colours + c in curves:
                        xs, ys, on_grid = curves[p * n_colours + c]
                        ax.plot(xs / x_factor, ys[o] / f, color="0.75", lw=0.8, zorder=1,
                                gid="other_median", **({} if on_grid else _OTHER_MARK))
            if r == 0:  # one reference curve per panel, on a fine grid over the panel's x range
                idx = np.flatnonzero(panel == p)
                x_si = np.asarray(fit.group("constant_data")[spec["x"]].values, dtype=float)[idx]
                grid = np.linspace(x_si.min(), x_si.max(), _N_GRID) if idx.size else x_si
                ref = _reference(spec, fit, idx, grid) if idx.size else None
                if ref is not None:
                    ax.plot(grid / x_factor, ref / f, color="0.35", lw=1.1, ls="--", zorder=2, gid="reference")
                    reference_drawn = True
            ax.set_xlabel(x_label)
            ax.set_ylabel(axis_label(o, units.get(o)))
            title = panel_labels[p] if only is None else "\n".join(
                t for t in (panel_labels[p], colour_labels[only]) if t)
            if title and (r == 0 or len(observables) == 1):
                ax.set_title(_wrap(title, ax), fontsize=MIN_FONT + 1)
    if pair:
        _draw_pair_row(fit, rows[-1], cells, pair, spec, units, panel, colour, curves, palette)
    if transpose:  # x shared down each column (_grid): labelled under the bottom row only
        for row in rows:
            for ax in row[:-1]:
                ax.set_xlabel("")
                ax.tick_params(labelbottom=False)
    for ax in fig.axes:
        ax.autoscale(True)
    for row in rows:
        for ax in row:
            ax.grid(alpha=0.25, lw=0.5)
            ax.tick_params(labelsize=MIN_FONT + 1)
            for which in "xy":
                if (ax.get_xscale() if which == "x" else ax.get_yscale()) == "log":
                    _log_ticks(ax, which)
    if not multi:
        for ax in rows[0]:
            ax.label_outer()
    handles = [Line2D([], [], ls="", marker="o", mfc="0.5", mec="black", mew=0.4, ms=4, label="data")]
    if curve_drawn:
        handles.append(Line2D([], [], color="0.2", lw=1.6, label="posterior median"))
    if markers_drawn:
        handles.append(Line2D([], [], color="0.2", **_MEDIAN_MARK,
                              label="posterior median at the data's x\n(other covariates vary)" if not fallback
                              else "predictive median at the data's x\n(the model's noiseless curve\n"
                                   "cannot be computed here)"))
    handles += [Patch(color="0.2", alpha=0.34, label="50% predictive"),
                Patch(color="0.2", alpha=0.16, label="90% predictive")]
    clipped = {o: s for o, s in bands.attrs["below_floor"].items() if s > 0}
    if clipped:
        handles.append(Patch(color="none", label="bands clipped at 0\n(" + "; ".join(
            f"{s:.1%} of {o.replace('_', ' ')} draws\nbelow 0 under {_noise(fit, o)} noise" for o, s in clipped.items())
            + ")"))
    if split:
        handles.append(Line2D([], [], color="0.75", lw=0.8, label="other levels' medians",
                              **({} if curve_drawn else _OTHER_MARK)))
    if pair:
        handles.append(Line2D([], [], ls="", marker="o", mfc=_COLOURS[0], mec="none", alpha=0.4, ms=3,
                              label="predictive draws (pairs)"))
    if reference_drawn:
        handles.append(Line2D([], [], color="0.35", ls="--", lw=1.1, label="ball bearing, g(x) (eq. 2)"))
    if multi_colour:
        handles += [Patch(color=palette[c], label=lab) for c, lab in enumerate(colour_labels)]
    # below the panels, as many columns as fit the width: never over the title or the data
    longest = max(len(line) for h in handles for line in h.get_label().split("\n"))
    ncols = max(1, min(len(handles), int(fig.get_figwidth() / (longest * 0.6 * MIN_FONT / 72 + 0.6))))
    fig.legend(handles=handles, loc="outside lower center", fontsize=MIN_FONT, frameon=False, ncols=ncols)
    _suptitle(fig, f"{fit.model_id} on {fit.dataset_id}: posterior predictive")
    return _finish(fig, path)


def _palette(fit, columns, n):
    """One colour per colour level: ordered numeric levels along viridis (dark to green, its
    pale yellow end left out), categories in Okabe-Ito's colour-blind-safe set; both remain
    distinct to deuteranopes and in greyscale (viridis) or by hue (Okabe-Ito)."""
    if n <= 1:
        return [_COLOURS[0]]
    cd = fit.group("constant_data")
    numeric = all(np.issubdtype(cd[c].dtype, np.number) for c in columns) and len(columns) == 1
    if numeric or n > len(_COLOURS):
        cmap = matplotlib.colormaps["viridis"]
        return [matplotlib.colors.to_hex(cmap(v)) for v in np.linspace(0.0, 0.85, n)]
    return list(_COLOURS[:n])


def _noise(fit, observable):
    return fit.attr("setup").get("noise", {}).get(observable, "normal")


def _wrap(text, ax, fontsize=MIN_FONT + 1):
    """Panel title wrapped to its axes' width (at ~0.6 em a character), line by line. Under
    constrained layout the width is the axes' share of the figure less ~0.8 in of outer
    margins and 0.1 in between panels (the default subplot margins it has before the layout
    runs are wider, and wrapped "angle = 0 deg" as "angle = 0" / "deg"); a number is never
    parted from the words on either side ("= 0 deg", "contraction 1.00")."""
    import textwrap

    fig, spec = ax.figure, ax.get_subplotspec()
    if spec is not None and isinstance(fig.get_layout_engine(), matplotlib.layout_engine.ConstrainedLayoutEngine):
        width_in = (fig.get_figwidth() - 0.8) * len(spec.colspan) / spec.get_gridspec().ncols - 0.1
    else:
        width_in = ax.get_position().width * fig.get_figwidth()
    per_line = max(12, int(width_in * 72 / (0.6 * fontsize)))
    bound = re.sub(r"(?<=\S) (?=[-+]?\.?\d)|(?<=\d) (?=\S)", "\u00a0", text)  # a number stays with its neighbours
    return "\n".join(w for line in bound.split("\n") for w in textwrap.wrap(line, per_line)).replace("\u00a0", " ")


def _draw_pair_row(fit, axes, cells, pair, spec, units, panel, colour, curves, palette):
    """One observable against the other, an axes per (panel, colour level or None for all)
    cell: data, joint predictive draws, median curve."""
    xo, yo = pair
    od = fit.group("observed_data")
    fx, fy = _factor(units.get(xo)), _factor(units.get(yo))
    px, py = _ppc_draws(fit, xo, 20), _ppc_draws(fit, yo, 20)
    for ax, (p, only) in zip(axes, cells):
        for c in range(len(palette)) if only is None else [only]:
            idx = np.flatnonzero((panel == p) & (colour == c))
            if not len(idx):
                continue
            col = palette[c]
            ax.scatter(px[:, idx].ravel() / fx, py[:, idx].ravel() / fy, s=4, color=col, alpha=0.12,
                       lw=0, rasterized=True)
            ax.scatter(od[xo].values[idx] / fx, od[yo].values[idx] / fy, s=12, color=col,
                       edgecolor="black", linewidth=0.4, zorder=3, gid="data")
            _, ys, on_grid = curves[p * len(palette) + c]  # markers where the main panels have them
            ax.plot(ys[xo] / fx, ys[yo] / fy, color=col, zorder=4,
                    **({"lw": 1.6} if on_grid else _MEDIAN_MARK))
        ax.set_xlabel(axis_label(xo, units.get(xo)))
        ax.set_ylabel(axis_label(yo, units.get(yo)))
        ax.set_xscale(spec["yscale"])
        ax.set_yscale(spec["yscale"])


# ---- inference plots ----------------------------------------------------------------------
def _param_label(name, unit):
    """Parameter names are kept as written (``E_star [Pa]``), unlike column labels."""
    return name if unit is None else f"{name} [{_unit_text(unit)}]"


def _slot_label(slot):
    return _param_label(slot["name"], slot["unit"])


def plot_pair(fit, path=None, *, var_names=None, max_draws=1500):
    """Corner plot: marginals on the diagonal, pairwise draws below, the MAP marked.

    Positive parameters on log axes (their sampling coordinate). By default every sampled
    scalar when there are at most 10, else the parameters not split by a column.
    """
    fit = as_fit(fit)
    slots = _slots(fit)
    if var_names is not None:
        slots = [s for s in slots if s["name"] in var_names or s["base"] in var_names]
    elif len(slots) > _MAX_PAIR:
        slots = [s for s in slots if s["level"] is None][:_MAX_PAIR]
    ds = fit.group("posterior")
    values = np.column_stack([_values(ds, s).ravel() for s in slots])
    if len(values) > max_draws:
        values = values[np.linspace(0, len(values) - 1, max_draws).astype(int)]
    mapv = fit.map
    d = len(slots)
    size = min(1.6 * d + 1.4, MAX_WIDTH)
    fig = Figure(figsize=(size, size))  # a fixed layout: constrained layout is slow on d*d axes
    # labels as "name\n[unit]"; with more than 5 parameters a cell is too small for a label
    # along its side: x labels turned upright, y labels written across, margins to fit them
    compact = d > 5
    labels = [_slot_label(s).replace(" [", "\n[") for s in slots]
    chars = max(len(line) for text in labels for line in text.split("\n"))
    label_in = chars * 0.6 * MIN_FONT / 72 + 0.15 if compact else 2 * 1.3 * MIN_FONT / 72 + 0.1
    fig.subplots_adjust(left=(0.55 + label_in) / size, bottom=(0.55 + label_in) / size, right=1 - 0.15 / size,
                        top=1 - 0.6 / size, wspace=0.1, hspace=0.1)
    gs = fig.add_gridspec(d, d)
    log = [_use_log(s, values[:, k]) for k, s in enumerate(slots)]
    axes = np.full((d, d), None, dtype=object)
    for i in range(d):
        for j in range(i + 1):
            ax = axes[i, j] = fig.add_subplot(gs[i, j])
            si, sj = slots[i], slots[j]
            if i == j:
                v = values[:, i]
                counts, edges = np.histogram(v, bins=np.geomspace(v.min(), v.max(), 40) if log[i] else 40)
                ax.stairs(counts, edges, fill=True, color=_COLOURS[0], alpha=0.7)  # one patch, not 40 bars
                ax.axvline(mapv[si["name"]], color=_MAP_COLOUR, lw=1)
                if log[i]:
                    ax.set_xscale("log")
            else:
                ax.scatter(values[:, j], values[:, i], s=1.5, alpha=0.25, color=_COLOURS[0], lw=0,
                           rasterized=True)
                ax.plot(mapv[sj["name"]], mapv[si["name"]], marker="x", color=_MAP_COLOUR, ms=5)
                if log[j]:
                    ax.set_xscale("log")
                if log[i]:
                    ax.set_yscale("log")
            if i == d - 1:
                ax.set_xlabel(labels[j], fontsize=MIN_FONT, rotation=90 if compact else 0)
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
                    axis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:.3g}"))
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
                    _log_ticks(axes[i, j], which, 3, sparse=True)
    _suptitle(fig, f"{fit.model_id} on {fit.dataset_id}: posterior draws (MAP in orange-red)")
    return _finish(fig, path)


def _ranks(x):
    """Pooled ranks (0..1) of an array of any shape."""
    flat = x.ravel()
    r = np.empty(len(flat))
    r[np.argsort(flat, kind="stable")] = np.arange(len(flat))
    return (r / max(len(flat) - 1, 1)).reshape(x.shape)


def plot_trace(fit, path=None, *, var_names=None, n_groups=4, max_points=300, max_walkers=8):
    """Walker traces (left) and rank histograms per walker group (right), one row per parameter.

    emcee walkers are not independent chains; the walkers are cut into ``n_groups`` groups
    and the ranks of their draws among all draws histogrammed: flat histograms that agree
    mean the groups sample the same distribution.
    """
    fit = as_fit(fit)
    slots = _slots(fit)
    if var_names is not None:
        slots = [s for s in slots if s["name"] in var_names or s["base"] in var_names]
    ds = fit.group("posterior")
    sampler = fit.attr("sampler")
    fig = _new_figure(10, 1.35 * len(slots) + 0.9)
    axes = fig.subplots(len(slots), 2, squeeze=False, width_ratios=[3, 1])
    for i, s in enumerate(slots):
        v = _values(ds, s)  # (walkers, draws)
        ax = axes[i, 0]
        step = max(1, v.shape[1] // max_points)  # the picture of a long chain, at a fraction of the ink
        shown = np.linspace(0, len(v) - 1, min(len(v), max_walkers)).astype(int)
        ax.plot(np.arange(0, v.shape[1], step), v[shown, ::step].T, lw=0.6, alpha=0.7)
        if _use_log(s, v):
            ax.set_yscale("log")
            _log_ticks(ax, "y")
        ax.set_ylabel(_slot_label(s), fontsize=8)
        ax.tick_params(labelsize=MIN_FONT)
        ranks = _ranks(v)
        groups = np.array_split(np.arange(len(v)), min(n_groups, len(v)))
        bins = np.linspace(0, 1, 21)
        axr = axes[i, 1]
        for g, members in enumerate(groups):
            h, _ = np.histogram(ranks[members].ravel(), bins=bins, density=True)
            axr.stairs(h, bins, color=_COLOURS[g % len(_COLOURS)], lw=1, baseline=None)
        axr.axhline(1.0, color="black", lw=0.6, ls=":")
        axr.set_ylim(0, None)
        axr.set_yticks([])
        axr.tick_params(labelsize=MIN_FONT)
        if i < len(slots) - 1:
            ax.tick_params(labelbottom=False)
            axr.tick_params(labelbottom=False)
    axes[-1, 0].set_xlabel(f"draw (after {sampler['burn']} burn-in steps, thinned by {sampler['thin']}); "
                           f"{min(len(v), max_walkers)} of {sampler['nwalkers']} walkers shown")
    axes[-1, 1].set_xlabel(f"rank (fraction), {len(groups)} walker groups")
    axes[0, 1].set_title("rank histograms (flat = mixed)", fontsize=9)
    _suptitle(fig, f"{fit.model_id} on {fit.dataset_id}: traces")
    return _finish(fig, path)


def _walker_groups(fit, n_groups=4):
    """The posterior as ``n_groups`` chains, each the draws of a block of emcee's walkers one
    walker after another (walkers are not independent chains; :func:`plot_trace` groups them
    the same way), as a DataTree for arviz-plots."""
    import xarray as xr

    post = fit.group("posterior")
    groups = np.array_split(np.arange(post.sizes["chain"]), min(n_groups, post.sizes["chain"]))
    size = min(len(g) for g in groups)
    out = {}
    for name, da in post.data_vars.items():
        da = da.transpose("chain", "draw", ...)
        parts = [da.isel(chain=g[:size]).values.reshape(1, -1, *da.shape[2:]) for g in groups]
        out[name] = (("chain", "draw", *da.dims[2:]), np.concatenate(parts))
    ds = xr.Dataset(out, coords={d: post[d] for d in post.dims if d not in ("chain", "draw")})
    ds = ds.assign_coords(chain=np.arange(len(groups)), draw=np.arange(ds.sizes["draw"]))
    return xr.DataTree.from_dict({"posterior": ds})


def plot_rank(fit, path=None, *, var_names=None, n_groups=4, ncols=4):
    """ArviZ's (arviz-plots) rank ECDF plot, the walkers pooled into ``n_groups`` chains, in
    the report's palette, width and >= 8 pt text (bench/results/arviz_plots.md measured these
    settings against the layout rules)."""
    fit = as_fit(fit)
    _ensure_backend()
    import arviz_plots as azp
    import matplotlib as mpl
    import matplotlib.pyplot as plt
    from arviz_base import rc_context, rcParams
    from cycler import cycler

    tree = _walker_groups(fit, n_groups)
    n = sum(var_names is None or s["base"] in var_names for s in _slots(fit))  # panels
    cols = max(1, min(ncols, n))
    size = (min(3.0 * cols, MAX_WIDTH), 2.3 * -(-n // cols) + 0.7)
    rc = {"axes.prop_cycle": cycler(color=list(_COLOURS)), "font.size": 9, "axes.titlesize": 9,
          "axes.labelsize": 9, "xtick.labelsize": MIN_FONT, "ytick.labelsize": MIN_FONT,
          "legend.fontsize": MIN_FONT}
    with mpl.rc_context(rc), rc_context({"plot.max_subplots": max(n, rcParams["plot.max_subplots"])}):
        pc = azp.plot_rank(tree, var_names=var_names, backend="matplotlib", col_wrap=cols,
                           figure_kwargs={"figsize": size, "figsize_units": "inches", "layout": "constrained"})
        fig = pc.viz["figure"].item()
        plt.close(fig)  # keep pyplot's registry clean; the Figure stays usable
        groups = tree["posterior"].sizes["chain"]
        _suptitle(fig, f"{fit.model_id} on {fit.dataset_id}: rank ECDF ({groups} walker groups)")
    return _finish(fig, path)


def plot_prior_posterior(fit, path=None, *, var_names=None, ncols=4):
    """Prior (line, exact density) against posterior (filled histogram), one panel per parameter.

    Positive parameters on log axes, densities per unit of the axis coordinate, each curve
    scaled to its peak; the title gives the contraction 1 - var(post)/var(prior) of
    :meth:`Fit.summary`: near 1 the data determined the parameter, near 0 the prior did.
    """
    fit = as_fit(fit)
    slots = _slots(fit, densities=True)
    if var_names is not None:
        slots = [s for s in slots if s["name"] in var_names or s["base"] in var_names]
    summary = fit.summary()
    ds = fit.group("posterior")
    ncols = min(ncols, len(slots))
    nrows = math.ceil(len(slots) / ncols)
    fig = _new_figure(3.0 * ncols, 2.3 * nrows + 0.7)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    for ax in axes.ravel()[len(slots):]:
        ax.set_visible(False)
    for k, s in enumerate(slots):
        ax = axes.ravel()[k]
        v = _values(ds, s).ravel()
        prior = s["prior"]
        lo_q, hi_q = (prior.ppf(np.array([0.005, 0.995])) if prior is not None else np.quantile(v, [0, 1]))
        lo_q = max(lo_q, np.min(v) * 1e-3) if s["log"] else lo_q
        log = _use_log(s, [lo_q, hi_q, v.min(), v.max()])
        t = np.log10(v) if log else v
        if log:
            lo_q, hi_q = np.log10(lo_q), np.log10(hi_q)
        lo, hi = min(lo_q, t.min()), max(hi_q, t.max())
        h, edges = np.histogram(t, bins=50, density=True)
        ax.stairs(h / h.max(), 10 ** edges if log else edges, fill=True, color=_COLOURS[0], alpha=0.55,
                  label="posterior")
        if prior is not None:
            grid = np.linspace(lo, hi, 400)
            xs = 10 ** grid if log else grid
            with np.errstate(divide="ignore", over="ignore"):
                dens = np.exp(prior.logpdf(xs)) * (xs * math.log(10) if log else 1.0)
            if np.nanmax(dens) > 0:
                ax.plot(xs, dens / np.nanmax(dens), color="black", lw=1.2, label="prior")
        if log:
            ax.set_xscale("log")
        ax.set_xlim(10 ** lo if log else lo, 10 ** hi if log else hi)
        if log:
            _log_ticks(ax)
        ax.set_ylim(0, 1.08)
        ax.set_yticks([])
        ax.set_xlabel(_slot_label(s), fontsize=9)
        ax.tick_params(labelsize=MIN_FONT)
        c = summary.loc[s["name"], "contraction"] if s["name"] in summary.index else np.nan
        ax.set_title(_wrap(f"{s['name']}: contraction {c:.2f}", ax, 9), fontsize=9)
    for row in axes:
        row[0].set_ylabel("density (scaled to peak)", fontsize=8)
    fig.legend(handles=[Patch(color=_COLOURS[0], alpha=0.55, label="posterior"),
                        Line2D([], [], color="black", lw=1.2, label="prior")],
               loc="outside right upper", fontsize=9, frameon=False)
    _suptitle(fig, f"{fit.model_id} on {fit.dataset_id}: prior vs posterior")
    return _finish(fig, path)


# ---- across fits ---------------------------------------------------------------------------
def _forest_rows(items, parameter):
    """(label, mean, lo, hi) rows and the parameter's unit from fits and/or summary tables."""
    from skinfit.results.fit import Fit

    if isinstance(items, dict):
        pairs = list(items.items())
    else:
        items = list(items) if isinstance(items, (list, tuple)) else [items]
        fits = [i if isinstance(i, pd.DataFrame) else as_fit(i) for i in items]
        datasets = {f.dataset_id for f in fits if isinstance(f, Fit)}
        models = {f.model_id for f in fits if isinstance(f, Fit)}
        pairs = []
        for k, f in enumerate(fits):
            if len(fits) == 1:
                label = ""
            elif not isinstance(f, Fit):
                label = str(k)
            elif len(datasets) > 1 and len(models) > 1:
                label = f"{f.model_id} / {f.dataset_id}"
            else:
                label = f.dataset_id if len(datasets) > 1 else f.model_id
            pairs.append((label, f))
    rows, unit = [], None
    pattern = re.compile(rf"^{re.escape(parameter)}(\[(.*)\])?$")
    for label, item in pairs:
        if not isinstance(item, pd.DataFrame):
            item = as_fit(item)
            unit = unit or parameter_units(item).get(parameter)
            table = item.summary()
            post = item.group("posterior")
            dims = ([d for d in post[parameter].dims if d not in ("chain", "draw")]
                    if parameter in post.data_vars else [])
        else:
            table, dims = item, []
        for name in table.index:
            m = pattern.match(str(name))
            if not m:
                continue
            level = m.group(2)
            level_text = f"{dims[0]} = {level}" if level is not None and dims else level
            text = " · ".join(t for t in (str(label), level_text) if t) or parameter
            rows.append((text, float(table.loc[name, "mean"]), float(table.loc[name, "hdi_3%"]),
                         float(table.loc[name, "hdi_97%"])))
    return rows, unit


def _population_interval(spec):
    """(centre, lo, hi) of a population distribution given as a mapping, draws or a scipy dist."""
    if hasattr(spec, "ppf"):
        lo, mid, hi = spec.ppf([0.03, 0.5, 0.97])
        return float(mid), float(lo), float(hi)
    if isinstance(spec, dict):
        if "mean" in spec and "sd" in spec and not {"lo", "hi"} & set(spec):
            m, sd = float(spec["mean"]), float(spec["sd"])
            return m, m - 1.881 * sd, m + 1.881 * sd  # central 94% of a normal
        centre = float(spec.get("median", spec.get("mean")))
        return centre, float(spec.get("lo", spec.get("hdi_3%"))), float(spec.get("hi", spec.get("hdi_97%")))
    draws = np.asarray(spec, dtype=float).ravel()
    lo, mid, hi = np.quantile(draws, [0.03, 0.5, 0.97])
    return float(mid), float(lo), float(hi)


def plot_forest(fits_or_tables, parameter, path=None, *, population=None, unit=None):
    """Posterior mean and 94% HDI of ``parameter`` across fits (subjects, conditions) and levels.

    Parameters
    ----------
    fits_or_tables : Fit, summary DataFrame, or a list / dict (label -> item) of them
        A parameter split by a column gives one row per level.
    parameter : str
    population : optional
        The population distribution of the parameter, drawn as a band over all rows and a
        row of its own: a mapping (``mean``/``sd``, or ``median``/``lo``/``hi``), an array of
        population draws, or a frozen scipy.stats distribution (94% central interval).
    unit : str, optional
        Unit for the axis label when only tables are given (fits carry their own).
    """
    rows, card_unit = _forest_rows(fits_or_tables, parameter)
    if not rows:
        raise InputError("plot_forest", f"no parameter {parameter!r} in the given fits or tables")
    unit = unit or card_unit
    labels = [r[0] for r in rows]
    mean = np.array([r[1] for r in rows])
    lo = np.array([r[2] for r in rows])
    hi = np.array([r[3] for r in rows])
    n = len(rows) + (1 if population is not None else 0)
    fig = _new_figure(6.4, 0.32 * n + 1.4)
    ax = fig.subplots()
    y = np.arange(len(rows))[::-1]
    ax.hlines(y, lo, hi, color=_COLOURS[0], lw=1.6)
    ax.plot(mean, y, "o", color=_COLOURS[0], ms=4, label="mean and 94% HDI")
    ticks, ticklabels = list(y), labels
    values = np.concatenate([lo, hi])
    if population is not None:
        c, plo, phi = _population_interval(population)
        ax.axvspan(plo, phi, color="0.6", alpha=0.2, lw=0)
        ax.axvline(c, color="0.3", lw=0.8, ls="--")
        ax.hlines(len(rows), plo, phi, color="black", lw=2.2)
        ax.plot(c, len(rows), "D", color="black", ms=5, label="population (94%)")
        ticks, ticklabels = ticks + [len(rows)], labels + ["population"]
        values = np.concatenate([values, [plo, phi]])
    ax.set_yticks(ticks, ticklabels, fontsize=8)
    ax.set_ylim(-0.7, n - 0.3)
    if np.all(values > 0) and values.max() / values.min() > 20:
        ax.set_xscale("log")
        _log_ticks(ax)
    ax.set_xlabel(_param_label(parameter, unit))
    ax.grid(axis="x", alpha=0.3, lw=0.5)
    fig.legend(fontsize=MIN_FONT, frameon=False, loc="outside lower center", ncols=2)
    _suptitle(fig, f"{parameter} across fits and conditions")
    return _finish(fig, path)


_EVIDENCE = ("log_Z", "logZ", "log_z", "log_evidence", "lnZ", "ln_Z")
_EVIDENCE_ERR = ("log_Z_err", "log_Z_se", "logZ_err", "log_Z_error", "se_log_Z", "log_Z_sd", "log_evidence_err",
                 "lnZ_err")
_LOO = ("elpd_loo", "elpd")
_LOO_ERR = ("elpd_loo_se", "elpd_se", "se")


def _pick(table, names):
    lower = {str(c).lower(): c for c in table.columns}
    return next((lower[n.lower()] for n in names if n.lower() in lower), None)


def plot_comparison(table, path=None, *, title=None):
    """Model comparison chart: log-evidence and/or LOO ELPD of each model relative to the best.

    ``table`` is any DataFrame with one row per model (index or a ``model`` column) and
    columns such as ``log_Z`` (+ ``log_Z_err``) and ``elpd_loo`` (+ ``se``); without them,
    its first numeric column is drawn as is.
    """
    table = table.copy()
    if "model" in table.columns:
        table = table.set_index("model")
    metrics = []
    for names, errs, text in ((_EVIDENCE, _EVIDENCE_ERR, "log evidence, log Z − best"),
                              (_LOO, _LOO_ERR, "ELPD (LOO) − best")):
        col = _pick(table, names)
        if col is not None:
            metrics.append((col, _pick(table, errs), f"{text} [nats]", True))
    if not metrics:
        numeric = [c for c in table.columns if pd.api.types.is_numeric_dtype(table[c])]
        if not numeric:
            raise InputError("plot_comparison", "the comparison table has no numeric column to draw")
        metrics.append((numeric[0], None, str(numeric[0]), False))
    fig = _new_figure(4.2 * len(metrics) + 1.5, 0.38 * len(table) + 1.6)
    axes = fig.subplots(1, len(metrics), squeeze=False, sharey=True)[0]
    y = np.arange(len(table))[::-1]
    for ax, (col, err, label, relative) in zip(axes, metrics):
        v = table[col].to_numpy(dtype=float)
        shown = v - np.nanmax(v) if relative else v
        e = table[err].to_numpy(dtype=float) if err is not None else None
        ax.errorbar(shown, y, xerr=e, fmt="o", color=_COLOURS[0], ecolor=_COLOURS[0], capsize=3, ms=5)
        if relative:
            ax.axvline(0, color="black", lw=0.7)
        ax.set_xlabel(label)
        ax.grid(axis="x", alpha=0.3, lw=0.5)
    axes[0].set_yticks(y, [str(i) for i in table.index], fontsize=9)
    _suptitle(fig, title or "model comparison (higher is better; bars: ± 1 standard error)")
    return _finish(fig, path)
