"""Names, units and labels: the units and long names of every variable of a fit's result tree
(CF-style ``units`` and ``long_name`` attrs: parameters and data in the SI units they are
stored in), the suffix of noise parameters, and the labels of the levels of grouping columns."""

import json
import math
import tomllib

from skinfit.io.units import si_unit, to_si

__all__ = ["variable_attrs", "annotate", "noise_suffix", "noise_parameter_names", "level_labels", "parameter_units",
           "display_unit_map", "derived_units", "sd_resolution", "round_to_sd"]


def noise_suffix(observables, obs):
    """The suffix of ``obs``'s noise parameters: none for a single observable, else ``_<obs>``."""
    return "" if len(observables) == 1 else f"_{obs}"


def noise_parameter_names(observables, noise):
    """Names of the noise parameters of ``observables`` with noise models ``noise`` (a mapping
    observable -> normal | student_t | lognormal): ``sigma`` (+ ``nu`` for Student-t), suffixed
    when several observables (:func:`noise_suffix`)."""
    names = []
    for obs in observables:
        suffix = noise_suffix(observables, obs)
        names.append(f"sigma{suffix}")
        if noise[obs] == "student_t":
            names.append(f"nu{suffix}")
    return names


def level_labels(frame, cols, dataset):
    """The label of each row's level of the columns ``cols`` of ``frame`` (a DataFrame of
    ``dataset``'s, values in SI): the values joined by commas, quantities in the units the data
    came in (``dataset.column(c).unit``) written with ``:g`` (``75`` for 75 V, ``0.5`` for 0.5 mN):
    the names of the levels of a split parameter (``alpha[75]``) and of a ``--by`` group."""
    parts = []
    for c in cols:
        values = frame[c]
        try:
            unit = dataset.column(c).unit
        except KeyError:
            unit = None
        if unit is not None:
            values = [f"{v / to_si(unit):g}" for v in values.to_numpy(dtype=float)]
        parts.append([str(v) for v in values])
    return [",".join(t) for t in zip(*parts)]


def derived_units(fit):
    """Derived quantity name -> SI unit, as the model card's ``[derived]`` table states them
    (recorded in a fit's root attribute ``derived``); empty for a card that derives none."""
    return json.loads(fit.attrs["derived"])["quantities"] if "derived" in fit.attrs else {}


def parameter_units(fit):
    """Parameter (or noise parameter, or derived quantity) name -> SI unit as stated in the
    model card, from a fit's root attributes (``fit.attrs``: ``model_card``, ``setup``, and
    ``derived`` when the card derives quantities)."""
    card = tomllib.loads(fit.attrs["model_card"])
    units = {p["name"]: p["unit"] for p in card.get("parameters", [])}
    for name, unit in derived_units(fit).items():
        units.setdefault(name, unit)
    obs_units = {o["name"]: o["unit"] for o in card.get("observables", [])}
    setup = json.loads(fit.attrs["setup"])
    observables = setup["observables"]
    for o in observables:
        suffix = noise_suffix(observables, o)
        units[f"sigma{suffix}"] = "1" if setup["noise"].get(o) == "lognormal" else obs_units.get(o, "1")
        units[f"nu{suffix}"] = "1"
    return units


def display_unit_map(fit):
    """Parameter name -> the unit its model card asks tables and figures to show it in
    (``display_unit``: kPa for a modulus, µm for a gap), for the parameters that name one, from
    a fit's root attribute ``model_card``."""
    card = tomllib.loads(fit.attrs["model_card"])
    return {p["name"]: p["display_unit"] for p in card.get("parameters", []) if p.get("display_unit")}


def variable_attrs(post):
    """name -> {"units": SI unit, "long_name": text} for the parameters, noise parameters,
    observables, covariates and other data columns of Posterior ``post``."""
    model, out = post.model, {}
    for q in (*model.parameters, *model.observables, *model.covariates):
        out[q.name] = {"units": q.unit, "long_name": q.name.replace("_", " ")
                       + (f": {q.description}" if q.description else "")}
    for o in post.observables:
        unit = next(q.unit for q in model.observables if q.name == o)
        suffix = noise_suffix(post.observables, o)
        lognormal = post.noise[o] == "lognormal"
        extra = " beyond its per-row standard errors" if o in getattr(post, "se", {}) else ""
        out[f"sigma{suffix}"] = {"units": "1" if lognormal else unit,
                                 "long_name": f"noise scale of {o}" + (" (of its log)" if lognormal else "") + extra}
        out[f"nu{suffix}"] = {"units": "1", "long_name": f"Student-t degrees of freedom of the noise of {o}"}
    for c in post.dataset.columns:
        if c.name not in out:
            out[c.name] = {"units": si_unit(c.unit) if c.unit else "", "long_name": c.name.replace("_", " ")}
    if model.derived:
        for name, unit in model.derived["quantities"].items():
            out[name] = {"units": unit, "long_name": f"{name.replace('_', ' ')} (derived)"}
    return out


def annotate(tree, post):
    """Set ``units`` and ``long_name`` on every variable of ``tree`` (a DataTree) that
    :func:`variable_attrs` knows; the log-likelihood's values are in nats."""
    attrs = variable_attrs(post)
    for group in tree.children:
        node = tree[group]
        for var in node.data_vars:
            if group == "log_likelihood":
                node[var].attrs.update({"units": "1", "long_name": f"pointwise log-likelihood of {var} (nats)"})
            elif var in attrs:
                node[var].attrs.update(attrs[var])
    return tree


def sd_resolution(sd):
    """The power of ten of the second significant digit of an uncertainty ``sd`` (``-4`` for
    sd 0.0123: estimates are given to 0.0001), or None when ``sd`` is not a finite number > 0."""
    try:
        sd = float(sd)
    except (TypeError, ValueError):
        return None
    if not math.isfinite(sd) or sd <= 0:
        return None
    return math.floor(math.log10(sd)) - 1


def round_to_sd(value, sd):
    """``value`` as text at the precision its uncertainty ``sd`` allows: rounded to the decimal
    place of the second significant digit of ``sd`` (the convention of measurement reporting:
    ``round_to_sd(2.409213, 0.0123)`` is ``"2.409"``, ``round_to_sd(0.0123, 0.0123)`` is
    ``"0.012"``); in powers of ten beyond 1e-4 .. 1e6 (``"2.41e-07"``). Without a usable ``sd``
    (0, NaN) three significant digits; a NaN value is ``"nan"``."""
    value = float(value)
    if not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    q = sd_resolution(sd)
    if q is None:
        return f"{value:.3g}"
    rounded = round(value, -q)
    if rounded == 0:  # zero at the resolution: its decimals say how close to zero
        return f"{0:.{-q}f}" if -6 <= q < 0 else "0"
    magnitude = math.floor(math.log10(abs(rounded)))
    if -4 <= magnitude < 6:
        return f"{rounded:.{max(0, -q)}f}"
    return f"{rounded:.{max(0, magnitude - q)}e}"
