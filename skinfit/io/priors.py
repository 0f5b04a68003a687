"""Prior files (priors/<id>.toml): one literature-sourced prior per parameter.

Each prior is a scipy.stats distribution from a closed vocabulary, truncated to the
parameter's physical ``bounds`` and renormalised there, so every prior is proper and its
log-density is normalised (evidence from different models is comparable).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from types import MappingProxyType

import numpy as np

from skinfit.errors import InputError
from skinfit.io.arguments import check_id
from skinfit.io.paths import display
from skinfit.io.references import check_file_source
from skinfit.io.toml import available, find_file, read_toml, require, sha256_file

__all__ = ["Prior", "PriorSet", "load_priors", "list_priors", "check_priors_for", "check_physical", "prior_groups",
           "DISTRIBUTIONS", "LOG_DENSITIES", "SCIPY_NAMES"]


def _stats():
    """scipy.stats, imported on first use (~0.5 s): a saved fit's priors are read, and its trace
    and corner plots drawn, from their bounds alone (:func:`parse_prior` with ``check_mass=False``)."""
    from scipy import stats  # here, not with the module: see the docstring (tests/test_startup.py)

    return stats


# name -> (required arguments, factory(args, lo, hi) -> frozen scipy distribution)
DISTRIBUTIONS = {
    "uniform": ((), lambda a, lo, hi: _stats().uniform(loc=lo, scale=hi - lo)),
    "loguniform": ((), lambda a, lo, hi: _stats().loguniform(lo, hi)),
    "normal": (("loc", "scale"), lambda a, lo, hi: _stats().norm(loc=a["loc"], scale=a["scale"])),
    "lognormal": (("median", "sigma"), lambda a, lo, hi: _stats().lognorm(s=a["sigma"], scale=a["median"])),
    "halfnormal": (("scale",), lambda a, lo, hi: _stats().halfnorm(scale=a["scale"])),
    "gamma": (("shape", "scale"), lambda a, lo, hi: _stats().gamma(a=a["shape"], scale=a["scale"])),
    "beta": (("a", "b"), lambda a, lo, hi: _stats().beta(a["a"], a["b"])),
}
#: Distribution name -> its closed-form log-density without the normalising constant, a numpy
#: function ``(x, args, lower, upper)`` of values ``x`` (any shape) and the prior's arguments
#: (:attr:`Prior.args`, each a scalar or an array broadcasting with ``x``); the constant is
#: :attr:`Prior._log_norm`. The sampling hot path evaluates priors with these, one call per family.
LOG_DENSITIES = {
    "uniform": lambda x, a, lo, hi: np.zeros_like(x),
    "loguniform": lambda x, a, lo, hi: -np.log(x),
    "normal": lambda x, a, lo, hi: -0.5 * ((x - a["loc"]) / a["scale"]) ** 2,
    "lognormal": lambda x, a, lo, hi: -np.log(x) - 0.5 * (np.log(x / a["median"]) / a["sigma"]) ** 2,
    "halfnormal": lambda x, a, lo, hi: -0.5 * (x / a["scale"]) ** 2,
    "gamma": lambda x, a, lo, hi: (a["shape"] - 1) * np.log(x) - x / a["scale"],
    "beta": lambda x, a, lo, hi: (a["a"] - 1) * np.log(x) + (a["b"] - 1) * np.log1p(-x),
}
#: How scipy.stats writes each family, for messages: a prior file takes the names above (and
#: Python code takes scipy's frozen distributions themselves: skinfit.io.user_priors).
SCIPY_NAMES = {
    "uniform": "scipy's uniform(loc, scale) is bounds = [loc, loc + scale]",
    "loguniform": "scipy's loguniform(a, b) is bounds = [a, b]",
    "normal": "scipy's norm(loc, scale) is normal loc, scale",
    "lognormal": "scipy's lognorm(s, scale) is lognormal median = scale, sigma = s",
    "halfnormal": "scipy's halfnorm(scale) is halfnormal scale, bounds from 0",
    "gamma": "scipy's gamma(a, scale) is gamma shape = a, scale = scale",
    "beta": "scipy's beta(a, b) is beta a, b on [0, 1]",
}
_POSITIVE_ARGS = {"scale", "sigma", "median", "shape", "a", "b"}


@dataclass(frozen=True)
class Prior:
    """A truncated, renormalised prior on one parameter (SI units)."""

    name: str
    dist: str
    args: MappingProxyType
    lower: float
    upper: float
    source: str

    @cached_property
    def frozen(self):
        return DISTRIBUTIONS[self.dist][1](self.args, self.lower, self.upper)

    @cached_property
    def _cdf_bounds(self):
        f = self.frozen
        return float(f.cdf(self.lower)), float(f.cdf(self.upper))

    @cached_property
    def log_mass(self):
        """log of the untruncated prior's mass inside the bounds (the renormalisation)."""
        f = self.frozen
        lo = f.logcdf(self.lower) if np.isfinite(self.lower) else -np.inf
        hi = f.logcdf(self.upper) if np.isfinite(self.upper) else 0.0
        if hi - lo < 1e-12:  # both in one tail: use survival functions
            lo, hi = f.logsf(self.upper), f.logsf(self.lower)
        if hi - lo < 1e-12:  # bounds narrow beside the spread: the density is flat there (Simpson)
            from scipy import special  # with scipy.stats (frozen above), never on a path without it

            a, b = self.lower, self.upper
            return float(special.logsumexp(f.logpdf([a, 0.5 * (a + b), b]), b=[1.0, 4.0, 1.0])
                         + math.log((b - a) / 6.0))
        return float(hi + math.log1p(-math.exp(lo - hi)) if np.isfinite(lo) else hi)

    def logpdf(self, x):
        """Normalised log-density; -inf outside the bounds.  Vectorised, closed form in numpy
        (the hot path of sampling); tests check it against scipy.stats."""
        x = np.asarray(x, dtype=float)
        inside = (x >= self.lower) & (x <= self.upper)
        with np.errstate(divide="ignore", invalid="ignore"):
            lp = LOG_DENSITIES[self.dist](x, self.args, self.lower, self.upper) - self._log_norm
        return np.where(inside, lp, -np.inf)

    @cached_property
    def _log_norm(self):
        """log mass inside the bounds plus the density's own constant (for the closed forms)."""
        a, lo, hi = self.args, self.lower, self.upper
        const = {
            "uniform": math.log(hi - lo) if np.isfinite(hi - lo) else 0.0,
            "loguniform": math.log(math.log(hi / lo)) if lo > 0 else 0.0,
            "normal": math.log(a.get("scale", 1.0)) + 0.5 * math.log(2 * math.pi),
            "lognormal": math.log(a.get("sigma", 1.0)) + 0.5 * math.log(2 * math.pi),
            "halfnormal": math.log(a.get("scale", 1.0)) + 0.5 * math.log(math.pi / 2),
            "gamma": math.lgamma(a.get("shape", 1.0)) + a.get("shape", 1.0) * math.log(a.get("scale", 1.0)),
            "beta": math.lgamma(a.get("a", 1.0)) + math.lgamma(a.get("b", 1.0))
                    - math.lgamma(a.get("a", 1.0) + a.get("b", 1.0)),
        }[self.dist]
        mass = 0.0 if self.dist in ("uniform", "loguniform") else self.log_mass
        return const + mass

    def ppf(self, u):
        """Quantile function of the truncated prior (u in [0, 1])."""
        c0, c1 = self._cdf_bounds
        if c1 - c0 > 1e-9:
            return np.clip(self.frozen.ppf(c0 + np.asarray(u) * (c1 - c0)), self.lower, self.upper)
        s0, s1 = self.frozen.sf(self.upper), self.frozen.sf(self.lower)  # far upper tail
        return np.clip(self.frozen.isf(s1 - np.asarray(u) * (s1 - s0)), self.lower, self.upper)

    def rvs(self, size, rng):
        return self.ppf(rng.uniform(size=size))

    def moments(self):
        """Mean and variance of the truncated prior (quadrature over its quantiles)."""
        u = (np.arange(4000) + 0.5) / 4000
        q = self.ppf(u)
        return float(q.mean()), float(q.var())

    def describe(self):
        args = ", ".join(f"{k}={v:g}" for k, v in self.args.items())
        return f"{self.dist}({args}) on [{self.lower:g}, {self.upper:g}]"


@dataclass(frozen=True)
class PriorSet:
    """The priors of one prior file, keyed by parameter name."""

    id: str
    model: str
    priors: MappingProxyType
    path: str = ""
    sha256: str = ""
    text: str = ""
    file: str = ""  # the absolute path of the file read ("" when not read from a file)

    def __getitem__(self, name):
        return self.priors[name]

    def __contains__(self, name):
        return name in self.priors

    def __iter__(self):
        return iter(self.priors)

    @property
    def names(self):
        return tuple(self.priors)

    def __repr__(self):
        return f"PriorSet({self.id!r}, {list(self.priors)})"


#: Narrowest prior range, relative to the bounds' size: walkers are placed and moved in float64
#: sampling coordinates, which need several significant digits across the range.
MIN_RELATIVE_WIDTH = 1e-8


def parse_prior(name, spec, where, check_mass=True):
    """The :class:`Prior` of parameter ``name`` from its table ``spec`` of a prior file
    (``where``, for errors). ``check_mass=False`` leaves out the checks that need scipy.stats
    (the bounds inside the distribution's support, some of its mass inside them): for a saved
    fit's priors read only for their bounds (its plots' axes), checked when it was made."""
    prefix = f"{name}."
    if not isinstance(spec, dict):
        raise InputError(where, "expected a table with dist, bounds, source", field=name)
    dist = require(spec, "dist", str, where, field_prefix=prefix)
    if dist not in DISTRIBUTIONS:
        raise InputError(where, f"unknown distribution {dist!r} (expected one of "
                         f"{', '.join(DISTRIBUTIONS)})", field=prefix + "dist")
    needed, _ = DISTRIBUTIONS[dist]
    extra = set(spec) - set(needed) - {"dist", "bounds", "source"}
    if extra:
        hint = f"; {SCIPY_NAMES[dist]}" if extra & {"s", "loc", "scale", "a", "b"} - set(needed) else ""
        raise InputError(where, f"unexpected keys {sorted(extra)} for a {dist} prior (expected "
                         f"{', '.join(needed) or 'no arguments'}, bounds, source{hint})", field=name)
    args = {}
    for arg in needed:
        value = require(spec, arg, float, where, field_prefix=prefix)
        if not math.isfinite(value):
            raise InputError(where, f"must be finite (got {value})", field=prefix + arg)
        if arg in _POSITIVE_ARGS and value <= 0:
            raise InputError(where, f"must be > 0 (got {value:g})", field=prefix + arg)
        args[arg] = value
    bounds = require(spec, "bounds", list, where, field_prefix=prefix)
    if len(bounds) != 2 or not all(isinstance(b, (int, float)) and not isinstance(b, bool) for b in bounds):
        raise InputError(where, f"expected [lower, upper] numbers (got {bounds!r})", field=prefix + "bounds")
    lo, hi = float(bounds[0]), float(bounds[1])
    if math.isnan(lo) or math.isnan(hi) or not lo < hi:
        raise InputError(where, f"expected lower < upper (got [{lo:g}, {hi:g}])", field=prefix + "bounds")
    if math.isfinite(hi - lo) and hi - lo <= MIN_RELATIVE_WIDTH * max(abs(lo), abs(hi)):
        raise InputError(where, f"bounds [{lo!r}, {hi!r}] are {hi - lo:.3g} apart, under {MIN_RELATIVE_WIDTH:g} of "
                         "their size: too narrow to sample (to fix the parameter, make it a constant of the "
                         "model card)", field=prefix + "bounds")
    if dist in ("uniform", "loguniform") and not (math.isfinite(lo) and math.isfinite(hi)):
        raise InputError(where, f"a {dist} prior on an infinite range is improper: give finite bounds",
                         field=prefix + "bounds")
    if dist == "loguniform" and lo <= 0:
        raise InputError(where, f"a loguniform prior needs lower > 0 (got {lo:g})", field=prefix + "bounds")
    source = require(spec, "source", str, where, field_prefix=prefix)
    if not source.strip():
        raise InputError(where, "every prior needs a literature source", field=prefix + "source")
    prior = Prior(name, dist, MappingProxyType(args), lo, hi, source)
    if not check_mass:
        return prior
    support = prior.frozen.support()
    if lo < support[0] or hi > support[1]:
        raise InputError(where, f"bounds [{lo:g}, {hi:g}] leave the support of {dist} "
                         f"[{support[0]:g}, {support[1]:g}]", field=prefix + "bounds")
    c0, c1 = prior._cdf_bounds
    if not (c1 - c0 > 1e-12 or prior.frozen.sf(lo) - prior.frozen.sf(hi) > 1e-300):
        raise InputError(where, f"the prior puts no mass inside its bounds [{lo:g}, {hi:g}]",
                         field=prefix + "bounds")
    return prior


def check_priors_for(priors, model):
    """A prior file serves the model its ``model`` field names, and no other."""
    if priors.model != model.id:
        raise InputError(priors.path or priors.id, f"is a prior file for model {priors.model!r}, not for "
                         f"{model.id!r} (copy it and set model = {model.id!r} if it applies)", field="model")


def check_physical(model, priors, noise_names):
    """Refuse a prior whose bounds leave the range the physics allows: the model card's
    ``physical = [lower, upper]`` of each parameter, and [0, inf] for the noise parameters
    ``noise_names`` (scales, Student-t degrees of freedom)."""
    ranges = {q.name: q.physical for q in model.parameters}
    ranges.update({n: (0.0, math.inf) for n in noise_names})
    for name, (lo, hi) in ranges.items():
        prior = priors[name]
        if prior.lower < lo or prior.upper > hi:
            raise InputError(priors.path or "priors", f"bounds [{prior.lower:g}, {prior.upper:g}] leave the "
                             f"physical range [{lo:g}, {hi:g}] of {name}, {_range_origin(model, name, noise_names)}",
                             field=f"{name}.bounds")


def _range_origin(model, name, noise_names):
    """Where the range :func:`check_physical` holds ``name`` to comes from, and what to do."""
    if name in noise_names:
        what = "a noise scale" if name.startswith("sigma") else "a Student-t's degrees of freedom"
        return (f"{what}, which cannot be negative: give it a prior on [0, inf] (a half-normal or log-normal, "
                "or bounds = [0, ...]; in Python skinfit.truncate(dist, 0, upper))")
    if model.file:
        return f"declared by model {model.id!r} in its card {model.file} ([[parameters]] physical)"
    return f"declared by model {model.id!r} (its [[parameters]] physical)"


def prior_groups(priors):
    """The priors of a vector of parameters (a sequence of :class:`Prior`, one per column)
    grouped by family for one vectorised call each: tuples (log-density of
    :data:`LOG_DENSITIES`, columns (m,), arguments {name: (m,) array}); uniform priors, constant
    inside their bounds, need no evaluation."""
    groups = {}
    for j, p in enumerate(priors):
        groups.setdefault(p.dist, []).append(j)
    out = []
    for dist, cols in groups.items():
        if dist == "uniform":
            continue
        members = [priors[j] for j in cols]
        args = {k: np.array([p.args[k] for p in members]) for k in members[0].args}
        out.append((LOG_DENSITIES[dist], np.array(cols), args))
    return tuple(out)


def load_priors(name: str | os.PathLike, *, check_mass: bool = True) -> PriorSet:
    """Load a prior file by id (``priors/<id>.toml``) or by path. ``check_mass=False``: every
    check but those that need scipy.stats (:func:`parse_prior`), for a caller that needs the
    file's identity (its sha256) and what it declares, not its distributions."""
    path = find_file("priors", name)
    doc, text = read_toml(path)
    where = display(path)
    model = check_id(require(doc, "model", str, where), where, field="model")
    if "id" in doc:
        check_id(doc["id"], where)
    priors = {}
    for key, spec in doc.items():
        if key in ("schema_version", "model", "id"):
            continue
        priors[key] = parse_prior(key, spec, where, check_mass)
        check_file_source(priors[key].source, path, where, f"{key}.source")  # a key of references.toml if shipped
    if not priors:
        raise InputError(where, "no priors defined")
    return PriorSet(id=doc.get("id", path.stem), model=model, priors=MappingProxyType(priors),
                    path=where, sha256=sha256_file(path), text=text, file=str(Path(path).resolve()))


def list_priors() -> list[str]:
    return sorted(available("priors"))
