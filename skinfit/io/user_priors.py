"""Priors given in Python: frozen scipy.stats distributions, :func:`truncate` d ones, or tables
in the prior-file syntax, turned into the :class:`~skinfit.io.priors.PriorSet` a fit uses and the
prior file (:func:`prior_file_text`) that gives the same priors from disk.

A scipy distribution's support is its bounds (``st.halfnorm(scale=0.1)`` on [0, inf));
``truncate(st.norm(0.5, 0.2), 0, 1)`` narrows them.  Each maps to a family of the prior files'
closed vocabulary (:data:`SCIPY_FAMILIES`), so the same priors written to a file give the same
numbers; scipy's other families are refused in one line naming those accepted.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from skinfit.errors import InputError, InputTypeError
from skinfit.io.arguments import shown
from skinfit.io.priors import PriorSet, parse_prior

__all__ = ["truncate", "Truncated", "SCIPY_FAMILIES", "as_prior_set", "prior_file_text", "toml_value",
           "noise_names_possible", "as_written"]

#: scipy.stats family -> (prior-file family, its arguments from scipy's {shape, loc, scale}, the
#: arguments that must keep scipy's default, support(arguments) -> (lower, upper)).
SCIPY_FAMILIES = {
    "norm": ("normal", lambda a: {"loc": a["loc"], "scale": a["scale"]}, {},
             lambda a: (-math.inf, math.inf)),
    "halfnorm": ("halfnormal", lambda a: {"scale": a["scale"]}, {"loc": 0.0}, lambda a: (0.0, math.inf)),
    "lognorm": ("lognormal", lambda a: {"median": a["scale"], "sigma": a["s"]}, {"loc": 0.0},
                lambda a: (0.0, math.inf)),
    "uniform": ("uniform", lambda a: {}, {}, lambda a: (a["loc"], a["loc"] + a["scale"])),
    "loguniform": ("loguniform", lambda a: {}, {"loc": 0.0}, lambda a: (a["a"] * a["scale"], a["b"] * a["scale"])),
    "reciprocal": ("loguniform", lambda a: {}, {"loc": 0.0}, lambda a: (a["a"] * a["scale"], a["b"] * a["scale"])),
    "gamma": ("gamma", lambda a: {"shape": a["a"], "scale": a["scale"]}, {"loc": 0.0}, lambda a: (0.0, math.inf)),
    "beta": ("beta", lambda a: {"a": a["a"], "b": a["b"]}, {"loc": 0.0, "scale": 1.0}, lambda a: (0.0, 1.0)),
}


@dataclass(frozen=True)
class Truncated:
    """A frozen scipy.stats distribution restricted to [lower, upper] and renormalised there
    (made by :func:`truncate`)."""

    dist: object
    lower: float
    upper: float

    def __repr__(self):
        return f"truncate({_scipy_text(self.dist)}, {self.lower!r}, {self.upper!r})"


def truncate(dist, lower: float, upper: float) -> Truncated:
    """``dist`` (a frozen scipy.stats distribution) restricted to [lower, upper]: a prior whose
    bounds are narrower than its support (``skinfit.truncate(st.norm(0.5, 0.2), 0.0, 1.0)``).
    The bounds must lie inside the support and hold some of its mass (checked when the priors
    are used, naming the parameter)."""
    _family(dist, "truncate", "dist")
    for name, value in (("lower", lower), ("upper", upper)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value):
            raise InputTypeError("truncate", f"expected a number (got {shown(value)})", field=name)
    if not lower < upper:
        raise InputError("truncate", f"expected lower < upper (got [{lower!r}, {upper!r}])", field="upper")
    return Truncated(dist, float(lower), float(upper))


def _family(dist, where, field):
    """(scipy family name, arguments {shape..., loc, scale}) of a frozen scipy.stats
    distribution, or InputError naming ``where`` and ``field``."""
    family = getattr(getattr(dist, "dist", None), "name", None)
    if family is None or not hasattr(dist, "args") or not hasattr(dist, "kwds"):
        if hasattr(dist, "name") and hasattr(dist, "freeze"):  # st.norm itself, not st.norm(...)
            raise InputTypeError(where, f"scipy.stats.{dist.name} is not frozen: give its parameters, e.g. "
                                        f"st.{dist.name}(...)", field=field)
        raise InputTypeError(where, "expected a frozen scipy.stats distribution (st.lognorm(s=1.0, scale=0.5)), "
                                    f"skinfit.truncate(...) or a prior-file table {{dist = ..., bounds = ...}} "
                                    f"(got {shown(dist)})", field=field)
    if family not in SCIPY_FAMILIES:
        raise InputError(where, f"scipy.stats.{family} is not a prior family skinfit has (expected one of "
                                f"{', '.join(SCIPY_FAMILIES)}; or skinfit.truncate(...) of one)", field=field)
    shapes = [s.strip() for s in (dist.dist.shapes or "").split(",") if s.strip()]
    names = [*shapes, "loc", "scale"]
    args = {"loc": 0.0, "scale": 1.0, **dict(zip(names, dist.args)), **dist.kwds}
    missing = [s for s in shapes if s not in args]
    if missing or set(args) - set(names):
        raise InputError(where, f"scipy.stats.{family} takes {', '.join(names)} (got "
                                f"{', '.join(map(str, [*args]))})", field=field)
    try:
        args = {k: float(args[k]) for k in names}  # scipy's order: shapes, loc, scale
    except (TypeError, ValueError):
        raise InputError(where, f"scipy.stats.{family}: expected numbers (got {shown(dist.kwds or dist.args)})",
                         field=field) from None
    return family, args


def _scipy_text(dist):
    try:
        family, args = _family(dist, "", "")
    except InputError:
        return repr(dist)
    return f"scipy.stats.{family}(" + ", ".join(f"{k}={v!r}" for k, v in args.items()) + ")"


def _spec_of(name, value, where):
    """The prior-file table (dist, arguments, bounds, source) of one prior given in Python."""
    if isinstance(value, Mapping):
        spec = dict(value)
        spec.setdefault("source", "given in Python")
        return spec
    lower = upper = None
    dist = value
    if isinstance(value, Truncated):
        dist, lower, upper = value.dist, value.lower, value.upper
    family, args = _family(dist, where, name)
    target, to_args, fixed, support = SCIPY_FAMILIES[family]
    for key, default in fixed.items():
        if args[key] != default:
            raise InputError(where, f"scipy.stats.{family} with {key}={args[key]!r}: skinfit's {target} prior has "
                                    f"{key}={default!r} (use skinfit.truncate for bounds)", field=name)
    lo, hi = support(args)
    spec = {"dist": target, **to_args(args), "bounds": [lo if lower is None else lower, hi if upper is None else upper],
            "source": _scipy_text(dist)}
    return spec


def noise_names_possible(model):
    """Every noise parameter name a fit of ``model`` may use (``sigma``, ``nu``; suffixed with
    ``_<observable>`` when the model has several observables)."""
    obs = model.observable_names
    suffixes = [""] if len(obs) == 1 else [f"_{o}" for o in obs]
    return [f"{n}{s}" for s in suffixes for n in ("sigma", "nu")]


def as_prior_set(priors, model, where="priors"):
    """The :class:`PriorSet` of ``priors`` (a mapping parameter -> frozen scipy distribution,
    :func:`truncate` d one or prior-file table) for ``model``; InputError naming the parameter for
    a prior the model has no parameter for, or one that is not a proper bounded prior."""
    if isinstance(priors, PriorSet):
        return priors
    if not isinstance(priors, Mapping):
        raise InputTypeError(where, f"expected a PriorSet or a mapping parameter -> scipy.stats distribution "
                                    f"(got {shown(priors)})")
    known = [*model.parameter_names, *noise_names_possible(model)]
    parsed = {}
    for name, value in priors.items():
        if name not in known:
            raise InputError(where, f"a prior for {name!r}, which model {model.id!r} does not have (parameters: "
                                    f"{', '.join(model.parameter_names)}; noise: "
                                    f"{', '.join(noise_names_possible(model))})", field=str(name))
        parsed[name] = parse_prior(name, _spec_of(name, value, where), where)
    text = prior_file_text(model.id, parsed)
    return PriorSet(id=model.id, model=model.id, priors=MappingProxyType(parsed), path=where,
                    sha256=_sha256(text), text=text)


def _sha256(text):
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def toml_value(value):
    """``value`` (str, bool, int, float or list of them) as TOML; floats exact (Python's repr)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value == math.inf else "-inf" if value == -math.inf
                                                else repr(value))
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML for {type(value).__name__}")


def prior_file_text(model_id, priors):
    """The prior file (TOML) of ``priors`` (name -> :class:`~skinfit.io.priors.Prior`) for model
    ``model_id``: read back, it gives the same priors, bit for bit."""
    lines = ["schema_version = 1", f"model = {toml_value(model_id)}"]
    for name, p in priors.items():
        key = name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else toml_value(name)
        lines += ["", f"[{key}]", f"dist = {toml_value(p.dist)}"]
        lines += [f"{k} = {toml_value(float(v))}" for k, v in p.args.items()]
        lines += [f"bounds = {toml_value([float(p.lower), float(p.upper)])}", f"source = {toml_value(p.source)}"]
    return "\n".join(lines) + "\n"


# prior-file family -> (scipy name, its arguments from the prior's, its support from its arguments)
_TO_SCIPY = {
    "normal": ("norm", lambda a, lo, hi: {"loc": a["loc"], "scale": a["scale"]}, lambda a: (-math.inf, math.inf)),
    "halfnormal": ("halfnorm", lambda a, lo, hi: {"scale": a["scale"]}, lambda a: (0.0, math.inf)),
    "lognormal": ("lognorm", lambda a, lo, hi: {"s": a["sigma"], "scale": a["median"]}, lambda a: (0.0, math.inf)),
    "uniform": ("uniform", lambda a, lo, hi: {"loc": lo, "scale": hi - lo}, None),
    "loguniform": ("loguniform", lambda a, lo, hi: {"a": lo, "b": hi}, None),
    "gamma": ("gamma", lambda a, lo, hi: {"a": a["shape"], "scale": a["scale"]}, lambda a: (0.0, math.inf)),
    "beta": ("beta", lambda a, lo, hi: {"a": a["a"], "b": a["b"]}, lambda a: (0.0, 1.0)),
}


def as_written(prior):
    """``(prior-file entry, Python)`` of a :class:`~skinfit.io.priors.Prior` as a user writes it:
    ``'dist = "lognormal", median = 0.5, sigma = 1.0, bounds = [0.0, inf]'`` and
    ``"st.lognorm(s=1.0, scale=0.5)"`` (in ``skinfit.truncate(..., lower, upper)`` when its
    bounds are narrower than the distribution's support)."""
    entry = ", ".join([f"dist = {toml_value(prior.dist)}", *(f"{k} = {toml_value(float(v))}"
                                                              for k, v in prior.args.items()),
                       f"bounds = {toml_value([float(prior.lower), float(prior.upper)])}"])
    name, args, support = _TO_SCIPY[prior.dist]
    dist = f"st.{name}(" + ", ".join(f"{k}={v!r}" for k, v in args(prior.args, prior.lower, prior.upper).items()) + ")"
    if support is not None and support(prior.args) != (prior.lower, prior.upper):
        dist = f"skinfit.truncate({dist}, {prior.lower!r}, {prior.upper!r})"
    return entry, dist
