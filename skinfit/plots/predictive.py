"""The numbers of the posterior-predictive check (:func:`skinfit.plots.ppc.plot_ppc`): what it
draws (:func:`plot_spec`), the predictive bands per observation (:func:`ppc_bands`) and the
posterior median curves, in the units the data came in.

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
import warnings

import numpy as np
import pandas as pd

from skinfit.errors import InputError
from skinfit.io.units import NONNEGATIVE, dimension
from skinfit.plots.reading import data_units, model_card, slot_values, unit_factor
from skinfit.results.fit import as_fit

__all__ = ["QUANTILES", "BAND_COLUMNS", "MAX_PANELS", "N_GRID", "plot_spec", "ppc_bands", "ppc_draws",
           "observable_floor", "median_curves", "ppc_median_curves", "reference_curve"]

#: Central posterior-predictive bands drawn by :func:`~skinfit.plots.ppc.plot_ppc` and returned by
#: :func:`ppc_bands`, and the columns that hold them.
QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)
BAND_COLUMNS = ("q05", "q25", "q50", "q75", "q95")
#: Most panels of a check of one observable (of two observables: 6).
MAX_PANELS = 12
_MAX_PANELS_MULTI = 6
_MAX_LEVELS = 12  # a numeric panel column with more distinct values is cut into ranges
_N_CURVE_DRAWS = 100  # posterior draws whose median is the curve
#: Points of a median or reference curve on its x grid.
N_GRID = 160


def plot_spec(fit):
    """What :func:`~skinfit.plots.ppc.plot_ppc` draws: x column, panel and colour columns, scales, reference.

    Read from the model card's ``[plot]`` table, with defaults from the data.
    """
    fit = as_fit(fit)
    card = model_card(fit)
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
                  and 2 <= _n_levels(cd[c].values) <= MAX_PANELS]
    limit = MAX_PANELS if len(observables) == 1 else _MAX_PANELS_MULTI
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
    shown = values.astype(float) / unit_factor(unit) if unit else values.astype(float)
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


def ppc_draws(fit, observable, max_draws=20000):
    """(draws, n) posterior-predictive draws of ``observable`` in SI, at most ``max_draws`` of
    them evenly spread over the chains."""
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
    card = model_card(fit)
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
    [q25, q75], the 90% band [q05, q95]: the bands :func:`~skinfit.plots.ppc.plot_ppc` draws.

    Quantiles of a non-negative observable (:func:`observable_floor`) are clipped at 0: a
    normal noise model puts some predictive draws below 0, which no measurement can be (the
    coverage of observed values >= 0 is unchanged). ``df.attrs["below_floor"]`` gives, per
    observable, the share of predictive draws that fell below it (0 for log-normal noise).
    """
    fit = as_fit(fit)
    spec = plot_spec(fit)
    units = data_units(fit)
    cd = fit.group("constant_data")
    od = fit.group("observed_data")
    x = np.asarray(cd[spec["x"]].values, dtype=float) / unit_factor(units.get(spec["x"]))
    panel, panel_labels = _keys(fit, spec["panels"], units)
    colour, colour_labels = _keys(fit, spec["colours"], units)
    frames, below = [], {}
    for o in spec["observables"]:
        f = unit_factor(units.get(o))
        draws = ppc_draws(fit, o)
        # np.quantile: the same numbers, vectorised (nanquantile goes column by column)
        q = (np.nanquantile if np.isnan(draws).any() else np.quantile)(draws, QUANTILES, axis=0)
        floor = observable_floor(fit, o)
        if floor is not None:
            below[o] = float(np.mean(draws < floor))
            q = np.maximum(q, floor)
        q = q / f
        frame = pd.DataFrame({"observable": o, "obs_id": od["obs_id"].values, "x": x,
                              "observed": od[o].values / f, "panel": panel, "colour": colour})
        for name, row in zip(BAND_COLUMNS, q):
            frame[name] = row
        frames.append(frame)
    out = pd.concat(frames, ignore_index=True)
    out.attrs.update(panel_labels=panel_labels, colour_labels=colour_labels, spec=spec, below_floor=below)
    return out


def _theta_draws(fit, post, n):
    """(n, d) natural parameter vectors evenly spread over the posterior draws."""
    ds = fit.group("posterior")
    cols = [slot_values(ds, {"base": s.base, "level": s.level}).ravel() for s in post.slots]
    theta = np.column_stack(cols)
    if len(theta) > n:
        theta = theta[np.linspace(0, len(theta) - 1, n).astype(int)]
    return theta


def median_curves(fit, spec, keys):
    """Posterior median of the noiseless prediction per (panel, colour) group (``keys``: the
    group code of each observation).

    On a fine x grid when, within the group, every other covariate and every (split)
    parameter is constant; else at the observed x. Returns {group: (x_si, {obs: y_si}, on_grid)}.
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
            xs = np.geomspace(lo, hi, N_GRID) if spec["xscale"] == "log" and lo > 0 else np.linspace(lo, hi, N_GRID)
            cov = {name: (xs if name == x_name else np.full(N_GRID, values[idx[0]]))
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


def ppc_median_curves(fit, bands, keys):
    """Fallback of :func:`median_curves`: the posterior-predictive median at the observed x."""
    units = data_units(fit)
    spec = bands.attrs["spec"]
    fx = unit_factor(units.get(spec["x"]))
    curves = {}
    for key in sorted(set(keys)):
        idx = np.flatnonzero(keys == key)
        out, xs = {}, None
        for o in spec["observables"]:
            rows = bands[bands["observable"] == o].iloc[idx]
            med = rows.groupby("x")["q50"].mean() * unit_factor(units.get(o))
            xs, out[o] = med.index.to_numpy() * fx, med.to_numpy()
        curves[key] = (xs, out, False)
    return curves


def reference_curve(spec, fit, idx, xs_si):
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
