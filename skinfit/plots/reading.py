"""What the figures read from a saved fit: its model card, the units of its data and
parameters, its sampled scalars (slots) and their axis labels."""

import re
import tomllib

import numpy as np

from skinfit.io.labels import display_unit_map
from skinfit.io.labels import parameter_units as card_parameter_units
from skinfit.io.priors import parse_prior
from skinfit.io.units import pretty_unit, to_si, unit_mathtext
from skinfit.results.fit import as_fit

__all__ = ["model_card", "data_units", "unit_factor", "axis_label", "param_label",
           "parameter_units", "saved_priors", "sampled_slots", "use_log", "slot_values"]


def model_card(fit):
    """The model card saved in ``fit``, as a dict."""
    return tomllib.loads(fit.attrs["model_card"])


def data_units(fit):
    """Column -> unit the data came in (dataset card), falling back to the model card's SI unit."""
    card = model_card(fit)
    units = {q["name"]: q["unit"] for key in ("observables", "covariates") for q in card.get(key, [])}
    units.update(fit.attr("data_units") if "data_units" in fit.attrs else fit.attr("units"))
    return units


def unit_factor(unit):
    """Factor from SI to ``unit`` (divide SI values by it); 1 for units skinfit does not convert."""
    try:
        return to_si(unit)
    except ValueError:  # a symbolic model unit such as N^n_z
        return 1.0


def _unit_text(unit):
    """A unit in a figure label as a physicist writes it: ``N·s/m``, ``m²/Nᵐ``
    (:func:`skinfit.io.units.pretty_unit`); mathtext where plain text has no superscript for
    a power (``N^n_z``); ``-`` for a dimensionless quantity; a power of ten before the unit
    (``10⁻⁶ m^2/N^m``, :func:`skinfit.plots.style.plain_scale`) kept outside the mathtext."""
    if unit in ("1", "-", ""):
        return "-"
    power = re.match(r"10[\u207b\u2070\u00b9\u00b2\u00b3\u2074-\u2079]+ ", unit)  # "10⁻⁶ " of plain_scale
    if power:
        return power.group(0) + _unit_text(unit[power.end():])
    text = pretty_unit(unit)
    return unit_mathtext(unit) if "^" in text else text


def axis_label(name, unit=None):
    """``"normal_force", "mN"`` -> ``"normal force [mN]"``; dimensionless -> ``[-]``."""
    text = name.replace("_", " ")
    return text if unit is None else f"{text} [{_unit_text(unit)}]"


def param_label(name, unit):
    """``"E_star", "Pa"`` -> ``"E_star [Pa]"``: parameter names are kept as written, unlike
    column labels (:func:`axis_label`)."""
    return name if unit is None else f"{name} [{_unit_text(unit)}]"


def parameter_units(fit):
    """Parameter (or noise parameter) name -> SI unit as stated in the model card."""
    return card_parameter_units(as_fit(fit))


def saved_priors(fit, check_mass=True):
    """The prior of each parameter, from the prior file's text saved in the fit's root attrs
    (``check_mass``: see :func:`skinfit.io.priors.parse_prior`)."""
    doc = tomllib.loads(fit.attrs["priors_text"])
    return {k: parse_prior(k, v, "saved priors", check_mass) for k, v in doc.items()
            if k not in ("schema_version", "model", "id")}


def sampled_slots(fit, densities=False):
    """The sampled scalars: name, base, level, unit, display unit (or None), whether plotted on a log axis (a prior
    bounded below by 0) and, for a plot of the priors' ``densities``, the prior, checked against
    scipy.stats; the other plots read the bounds alone and do not import scipy.stats."""
    priors = saved_priors(fit, check_mass=densities)
    units, display = parameter_units(fit), display_unit_map(fit)
    out = []
    for s in fit.attr("slots"):
        prior = priors.get(s["base"])
        out.append({**s, "unit": units.get(s["base"]), "display": display.get(s["base"]),
                    "prior": prior if densities else None,
                    "log": prior is not None and prior.lower >= 0})
    return out


def use_log(slot, values):
    """Log axis for a positive parameter whose values span more than a factor of 10."""
    values = np.asarray(values, dtype=float)
    return bool(slot["log"] and values.min() > 0 and values.max() > 10 * values.min())


def slot_values(ds, slot):
    """(chain, draw) values of one slot from a posterior/prior Dataset."""
    da = ds[slot["base"]]
    if slot["level"] is not None:
        dim = next(d for d in da.dims if d not in ("chain", "draw"))
        da = da.sel({dim: slot["level"]})
    return np.asarray(da.transpose("chain", "draw").values, dtype=float)
