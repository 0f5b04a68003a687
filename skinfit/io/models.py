"""Model cards (models/<id>.toml): validated at load time into frozen Model objects.

A card names its forward function (and ``[sampling]`` / ``[derived]`` functions) as
``module:function`` or a registered name; only functions registered for that role in
:mod:`skinfit.io.registry` can be named (nothing in a card is evaluated as code).  Units on a
card are SI (:func:`skinfit.io.units.check_model_unit`).
"""

from __future__ import annotations

import hashlib
import math
import os
import tomllib
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:  # pandas in annotations only: ``skinfit models`` does without it
    import pandas as pd

from skinfit.errors import InputError, InputTypeError, SupportWarning
from skinfit.io.arguments import check_id, check_mapping, check_path, shown
from skinfit.io.forward_check import forward_error, undefined_hint, validated
from skinfit.io.paths import display
from skinfit.io.references import check_file_source
from skinfit.io.registry import lookup, register, resolve
from skinfit.io.toml import available, find_file, read_toml, require, sha256_file
from skinfit.io.units import check_model_unit, dimension, same_dimension
from skinfit.io.user_functions import adapt, check_source_hash, function_card, import_function
from skinfit.io.user_priors import as_prior_set

__all__ = ["Model", "Quantity", "load_model", "list_models", "parse_model_text", "resolve_forward", "check_id",
           "check_constant", "resolve_noise", "resolve_constants", "resolve_split", "NOISE_MODELS", "user_forward",
           "function_model", "write_card"]

NOISE_MODELS = ("normal", "student_t", "lognormal")


@dataclass(frozen=True)
class Quantity:
    """A named observable, covariate or parameter of a model card."""

    name: str
    unit: str
    description: str = ""
    noise: str | None = None  # observables only
    optional: bool = False  # covariates only: NaN allowed by design
    physical: tuple = (-math.inf, math.inf)  # parameters only: the range the physics allows
    display_unit: str = ""  # parameters only: the unit tables and figures show values in (kPa for a modulus)
    rope: tuple | None = None  # parameters only: a region of practical equivalence of contrasts (ratio or difference)


def resolve_forward(ref, where="forward", role="forward"):
    """The function a card names for ``role`` (forward, shear, shift, derived), looked up in
    :mod:`skinfit.io.registry`; InputError naming ``where`` if it is not registered for that role."""
    return resolve(role, ref, where)


@dataclass(frozen=True)
class Model:
    """A published model: its forward function and what its card says about it."""

    id: str
    title: str
    source: str
    forward_ref: str
    observables: tuple
    covariates: tuple
    parameters: tuple
    constants: MappingProxyType
    constant_sources: MappingProxyType
    variants: tuple = ()
    support: str = ""
    split: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    plot: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    shear: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    linear: tuple = ()  # parameters sampled in natural units although positive
    shift: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))  # name -> function of constants
    product: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))  # name -> {partner: exponent}
    derived: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    path: str = ""
    sha256: str = ""
    card_text: str = ""
    file: str = ""  # the absolute path of the card read ("" when not read from a file)
    user_function: bool = False  # the card names a ``function = "module:qualname"`` f(p, x), not a ``forward``
    function_sha256: str = ""  # sha256 of that function's source ("" when Python had none)
    saved: bool = False  # a card saved in a fit: its function may be imported by module and name
    function: object = field(default=None, compare=False, repr=False)  # Model.from_function's, adapted

    @property
    def forward(self):
        """The forward function ``(p, x, c) -> (y, ok)`` (:mod:`skinfit.io.forward_check`)."""
        if not self.user_function:
            return resolve("forward", self.forward_ref, self.path)
        return self.function if self.function is not None else user_forward(self)

    def __getstate__(self):
        """Pickled (a Model handed to worker processes) with its read-only tables as dicts that
        unpickle as read-only tables again; a function model's function by module and name
        (:class:`skinfit.io.user_functions.UserForward`)."""
        return {k: _picklable(v) for k, v in self.__dict__.items()}

    @classmethod
    def from_function(cls, func, *, observable, covariates, parameters, id=None, title=None, source=None) -> Model:
        """A model whose forward model is the Python function ``func(p, x)``.

        ``p`` maps each parameter to a (k, 1) array of k parameter draws, ``x`` each covariate
        to an (n,) array, all SI; ``func`` returns the (k, n) array of the observable, or a dict
        observable -> (k, n) array.  It is checked on a few prior draws before a fit (shape,
        finiteness, vectorisation over draws).

        The model is recorded by the function's ``module:qualname`` and the sha256 of its source
        (none for a function Python has no source for); a saved fit needs the function only to
        evaluate the model again.  The function is registered (role ``function``) in this
        process, so the card :meth:`to_card` writes loads here as well (docs/own-model.md).

        Parameters
        ----------
        observable : (name, unit) or (name, unit, noise), a sequence of them, or a mapping name -> unit
            The observable(s), SI unit; noise ``normal`` (default), ``student_t`` or ``lognormal``.
        covariates, parameters : mapping name -> unit (or name -> (unit, description))
            SI units; a power may name a parameter (``"N^(1-n)"``).
        id, title, source : str, optional
            Default: the function's name; a title naming it; ``source`` free text (your paper).
        """
        return function_model(cls, func, observable, covariates, parameters, id, title, source)

    def to_card(self, folder: str | os.PathLike, priors=None, *, overwrite: bool = False) -> dict:
        """Write this model's card to ``folder/models/<id>.toml`` and, given ``priors`` (a
        PriorSet or a mapping parameter -> scipy.stats distribution), its prior file to
        ``folder/priors/<id>.toml``: the files a plug-in package ships (docs/own-model.md).
        Returns {"model": path, "priors": path}; InputError for a file already there unless
        ``overwrite``."""
        return write_card(self, folder, priors, overwrite)

    @property
    def parameter_names(self):
        return tuple(p.name for p in self.parameters)

    @property
    def observable_names(self):
        return tuple(o.name for o in self.observables)

    @property
    def covariate_names(self):
        return tuple(c.name for c in self.covariates)

    def evaluate(self, params, covariates, constants=None):
        """Raw forward call: ``(y, ok)`` with ``y`` a dict of (k, n) arrays, ``ok`` bool (k, n).

        ``params`` values broadcast to (k, n); ``covariates`` is a mapping of (n,) SI arrays.
        """
        c = dict(self.constants)
        if constants:
            c.update(constants)
        y, ok = self.forward(params, covariates, c)
        return y, ok

    def derive(self, params, covariates, constants=None):
        """Derived quantities of the card's ``[derived]`` table: dict name -> array (k, n)."""
        c = {**self.constants, **(constants or {})}
        out = resolve("derived", self.derived["function"], self.path)(params, covariates, c)
        if set(out) != set(self.derived["quantities"]):
            raise InputError(self.path, f"{self.derived['function']} returns {sorted(out)}, the card "
                             f"declares {sorted(self.derived['quantities'])}", field="derived.quantities")
        return out

    def predict(self, params: Mapping[str, ArrayLike], data: pd.DataFrame | Mapping[str, ArrayLike], *,
                constants: Mapping[str, float] | None = None, return_valid: bool = False):
        """Predicted observable(s) at the covariates of ``data``.

        Parameters
        ----------
        params : mapping name -> float or array of shape (k,)
            An ensemble of k parameter vectors (SI units); floats give one vector.
        data : pandas.DataFrame or mapping of (n,) arrays
            SI covariates, columns named as in the model card.

        Returns
        -------
        ndarray of shape (n,) when every parameter is a float, else (k, n); a dict of such
        arrays (keyed by observable) for a model with several observables.  Points outside the
        model's physical support are NaN and a :class:`SupportWarning` says so (or pass
        ``return_valid=True`` to get ``(y, valid)`` instead).
        """
        missing = set(self.parameter_names) - set(params)
        if missing:
            raise InputError(f"model {self.id}", f"missing parameters {sorted(missing)}",
                             field="params")
        scalar = all(np.ndim(params[name]) == 0 for name in self.parameter_names)
        p = {}
        for name in self.parameter_names:
            try:
                p[name] = np.asarray(params[name], dtype=float).reshape(-1, 1)
            except (TypeError, ValueError):
                raise InputError(f"model {self.id}", f"expected a number or an array of numbers (got "
                                 f"{type(params[name]).__name__})", field=f"params.{name}") from None
            if not np.isfinite(p[name]).all():
                raise InputError(f"model {self.id}", "expected finite numbers (got NaN or inf)", field=f"params.{name}")
        x = {}
        for cov in self.covariates:
            if cov.name not in data:
                raise InputError(f"model {self.id}", f"data has no covariate column {cov.name!r} "
                                 f"[{cov.unit}]", field="data")
            x[cov.name] = np.asarray(data[cov.name], dtype=float)
        n = len(next(iter(x.values()))) if x else len(data)
        k = max((v.shape[0] for v in p.values()), default=1)
        y, valid = validated(self, self.evaluate(p, x, constants), k, n, self.observable_names,
                             "called by predict()")
        out = {}
        for name, arr in y.items():
            if (valid & ~np.isfinite(arr)).any():
                i, j = np.argwhere(valid & ~np.isfinite(arr))[0]
                raise forward_error(self, f"returned {arr[i, j]} for {name!r} at row {j + 1} of draw {i + 1}, a point "
                                          f"it marks valid (ok True): {undefined_hint(self)}")
            arr[~valid] = np.nan  # (a new array: validated() copies)
            out[name] = arr[0] if scalar else arr
        valid = valid[0] if scalar else valid
        if not return_valid and not np.all(valid):
            warnings.warn(f"{self.id}: {np.size(valid) - np.count_nonzero(valid)} predictions lie "
                          f"outside the physical support ({self.support}); returned as NaN",
                          SupportWarning, stacklevel=2)
        result = out[self.observables[0].name] if len(out) == 1 else out
        return (result, valid) if return_valid else result

    def __repr__(self):
        return f"Model({self.id!r}, parameters={list(self.parameter_names)})"


class _Table(dict):
    """A read-only table (MappingProxyType) on its way through pickle: it unpickles as one."""

    def __reduce__(self):
        return _read_only, (dict(self),)


def _read_only(table):
    return MappingProxyType(table)


def _picklable(value):
    """``value`` with each MappingProxyType in it (nested ones too) a :class:`_Table`."""
    if isinstance(value, MappingProxyType):
        return _Table({k: _picklable(v) for k, v in value.items()})
    return value


def _quantities(doc, key, where, *, observable=False):
    items = require(doc, key, list, where, default=[] if key == "covariates" else ...)
    out = []
    for i, item in enumerate(items):
        prefix = f"{key}[{i}]."
        if not isinstance(item, dict):
            raise InputError(where, "expected a table", field=f"{key}[{i}]")
        name = require(item, "name", str, where, field_prefix=prefix)
        unit = require(item, "unit", str, where, field_prefix=prefix)
        reason = check_model_unit(unit)
        if reason:
            raise InputError(where, f"unknown unit {unit!r}: {reason}", field=prefix + "unit")
        desc = require(item, "description", str, where, field_prefix=prefix, default="")
        noise = None
        if observable:
            noise = require(item, "noise", str, where, field_prefix=prefix, default="normal")
            if noise not in NOISE_MODELS:
                raise InputError(where, f"unknown noise model {noise!r} (expected one of "
                                 f"{', '.join(NOISE_MODELS)})", field=prefix + "noise")
        optional = require(item, "optional", bool, where, field_prefix=prefix, default=False)
        physical = (-math.inf, math.inf)
        if key == "parameters" and "physical" in item:
            physical = require(item, "physical", list, where, field_prefix=prefix)
            if (len(physical) != 2 or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                              and not math.isnan(v) for v in physical)
                    or not physical[0] < physical[1]):
                raise InputError(where, f"expected [lower, upper] numbers with lower < upper, inf allowed "
                                 f"(got {physical!r})", field=prefix + "physical")
            physical = (float(physical[0]), float(physical[1]))
        display = ""
        if key == "parameters" and "display_unit" in item:
            display = require(item, "display_unit", str, where, field_prefix=prefix)
            try:
                same = same_dimension(display, unit)
            except ValueError as exc:
                raise InputError(where, str(exc), field=prefix + "display_unit") from None
            if not same:
                raise InputError(where, f"expected a unit of the dimension of {unit!r} (got {display!r}, a "
                                 f"{dimension(display)})", field=prefix + "display_unit")
        rope = None
        if key == "parameters" and "rope" in item:
            rope = require(item, "rope", list, where, field_prefix=prefix)
            if (len(rope) != 2 or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                                          for v in rope) or not rope[0] < rope[1]):
                raise InputError(where, "expected [low, high] finite numbers with low < high: the region of practical "
                                 "equivalence of a contrast (a ratio A / B for a positive parameter, e.g. [0.9, 1.1]; "
                                 f"else a difference A - B in SI) (got {rope!r})", field=prefix + "rope")
            rope = (float(rope[0]), float(rope[1]))
        out.append(Quantity(name, unit, desc, noise, optional, physical, display, rope))
    names = [q.name for q in out]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise InputError(where, f"duplicate names {sorted(dup)}", field=key)
    return tuple(out)


_CACHE = {}


def load_model(name: str | os.PathLike) -> Model:
    """Load a model card by id (``models/<id>.toml``) or by path.

    >>> load_model("electroadhesion").parameter_names[:3]
    ('E_star', 'tau0', 'd_air')
    """
    path = find_file("models", name)
    digest = sha256_file(path)
    key = (str(path.resolve()), digest)
    if key not in _CACHE:
        _CACHE[key] = _parse_model(path, digest)
    return _CACHE[key]


def _parse_model(path, digest):
    _, text = read_toml(path)
    model = replace(parse_model_text(text, display(path), digest), file=str(Path(path).resolve()))
    check_file_source(model.source, path, model.path, "source")  # keys into references.toml (shipped cards)
    for cname, source in model.constant_sources.items():
        if source:
            check_file_source(source, path, model.path, f"constants.{cname}.source")
    return model


def check_constant(name, value, where):
    """A model constant as a float, or InputError: every constant of a card (permittivities,
    thicknesses, radii, Poisson's ratios, exponents) is a finite number > 0."""
    if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0):
        raise InputError(where, f"expected a finite number > 0 (got {value!r})", field=f"constants.{name}")
    return float(value)


def resolve_noise(model, observables, noise, where):
    """The noise model of each of ``observables`` (those of ``model`` in the data): ``noise`` as a
    fit takes it (None: the card's; a name for all; a mapping observable -> name, the card's for
    the others), checked against :data:`NOISE_MODELS` (InputError naming ``where``)."""
    card_noise = {o.name: o.noise for o in model.observables}
    if noise is None or isinstance(noise, str):
        noise = {o: noise or card_noise[o] for o in observables}
    else:
        check_mapping(noise, where, "noise", "a noise model name or a mapping observable -> noise model")
        unknown = set(noise) - set(observables)
        if unknown:
            raise InputError(where, f"no observable {sorted(map(str, unknown))} in the data (observables: "
                             f"{', '.join(observables)})", field="noise")
        noise = {o: noise.get(o, card_noise[o]) for o in observables}
    for o, kind in noise.items():
        if kind not in NOISE_MODELS:
            raise InputError(where, f"unknown noise model {kind!r} for {o} (expected one of "
                             f"{', '.join(NOISE_MODELS)})", field="noise")
    return noise


def resolve_constants(model, constants, where):
    """The card's constants with ``constants`` (a mapping name -> number, optional) overriding
    them, each checked (:func:`check_constant`); InputError naming ``where`` for a name the card
    does not have."""
    check_mapping(constants, where, "constants", "a mapping constant name -> number")
    resolved = {**model.constants, **{k: check_constant(k, v, where) if k in model.constants else v
                                      for k, v in (constants or {}).items()}}
    unknown = set(constants or {}) - set(model.constants)
    if unknown:
        raise InputError(where, f"unknown constants {sorted(unknown)} (model constants: "
                         f"{', '.join(model.constants)})", field="constants")
    return resolved


def resolve_split(model, split, dataset, where):
    """Parameter -> tuple of grouping columns of ``dataset`` it is fitted once per level of:
    ``split`` (a mapping parameter -> column or list of columns; None: the card's ``[split]``),
    checked against the model's parameters and the data's columns (InputError naming ``where``)."""
    split = dict(model.split if split is None else
                 check_mapping(split, where, "split", "a mapping parameter -> column or list of columns"))
    out = {}
    for pname, cols in split.items():
        if not (isinstance(cols, str) or (isinstance(cols, (list, tuple))
                and cols and all(isinstance(c, str) for c in cols))):
            raise InputTypeError(where, f"expected {pname} = a column name or a list of column names "
                                 f"(got {shown(cols)})", field="split")
        if pname not in model.parameter_names:
            raise InputError(where, f"cannot split unknown parameter {pname!r} (parameters: "
                             f"{', '.join(model.parameter_names)})", field="split")
        cols = (cols,) if isinstance(cols, str) else tuple(cols)
        for c in cols:
            if c not in dataset.frame.columns:
                raise InputError(where, f"cannot split {pname!r} by {c!r}: no such column in "
                                 f"{dataset.path}", field="split")
        out[pname] = cols
    return out


def parse_model_text(text, where, digest, *, saved=False):
    """The :class:`Model` of a model card's TOML ``text`` (as read from a file, or as saved in a
    fit's root attributes: ``saved``), validated; ``where`` names it in errors and becomes its
    ``path``, ``digest`` is the sha256 of its file. Its ``source`` keys are not resolved here
    (:func:`load_model` checks them against the references files).  The function a ``saved``
    card names as ``function`` is looked for only when the model is evaluated."""
    doc = tomllib.loads(text)
    constants, sources = {}, {}
    for cname, spec in require(doc, "constants", dict, where, default={}).items():
        if isinstance(spec, dict):
            value = require(spec, "value", float, where, field_prefix=f"constants.{cname}.")
            sources[cname] = spec.get("source", "")
            unit = require(spec, "unit", str, where, field_prefix=f"constants.{cname}.", default="1")
            reason = check_model_unit(unit)
            if reason:
                raise InputError(where, f"unknown unit {unit!r}: {reason}", field=f"constants.{cname}.unit")
        elif isinstance(spec, (int, float)) and not isinstance(spec, bool):
            value = float(spec)
        else:
            raise InputError(where, f"expected a number or {{value=..., unit=..., source=...}} "
                             f"(got {spec!r})", field=f"constants.{cname}")
        constants[cname] = check_constant(cname, value, where)
    sampling = require(doc, "sampling", dict, where, default={})
    model = Model(
        id=check_id(require(doc, "id", str, where), where),
        title=require(doc, "title", str, where),
        source=require(doc, "source", str, where),
        forward_ref=_forward_key(doc, where),
        user_function="function" in doc,
        function_sha256=require(doc, "function_sha256", str, where, default=""),
        saved=saved,
        observables=_quantities(doc, "observables", where, observable=True),
        covariates=_quantities(doc, "covariates", where),
        parameters=_quantities(doc, "parameters", where),
        constants=MappingProxyType(constants),
        constant_sources=MappingProxyType(sources),
        variants=tuple(require(doc, "variants", list, where, default=[])),
        support=require(doc, "support", str, where, default=""),
        split=MappingProxyType(dict(require(doc, "split", dict, where, default={}))),
        plot=MappingProxyType(dict(require(doc, "plot", dict, where, default={}))),
        shear=MappingProxyType(dict(require(sampling, "shear", dict, where, field_prefix="sampling.", default={}))),
        linear=tuple(require(sampling, "linear", list, where, field_prefix="sampling.", default=[])),
        shift=MappingProxyType(dict(require(sampling, "shift", dict, where, field_prefix="sampling.", default={}))),
        product=MappingProxyType({k: MappingProxyType(dict(v)) if isinstance(v, dict) else v for k, v in
                                  require(sampling, "product", dict, where, field_prefix="sampling.",
                                          default={}).items()}),
        derived=_derived_table(doc, where),
        path=where,
        sha256=digest,
        card_text=text,
    )
    if not model.observables:
        raise InputError(where, "a model needs at least one observable", field="observables")
    if not model.user_function:
        resolve("forward", model.forward_ref, where)
    elif not saved:  # a card file: its function must be registered (a saved fit's is looked for when needed)
        user_forward(model)
    for pname in model.split:
        if pname not in model.parameter_names:
            raise InputError(where, f"split names unknown parameter {pname!r}", field=f"split.{pname}")
    for pname in model.linear:
        if pname not in model.parameter_names:
            raise InputError(where, f"names unknown parameter {pname!r}", field="sampling.linear")
    for kind, table in (("shear", model.shear), ("shift", model.shift)):
        for pname, ref in table.items():
            if pname not in model.parameter_names or not isinstance(ref, str):
                raise InputError(where, f"expected parameter = 'module:function' of a registered {kind} "
                                 f"function (got {pname} = {ref!r})", field=f"sampling.{kind}.{pname}")
            resolve(kind, ref, where, field=f"sampling.{kind}.{pname}")
    _check_products(model, where)
    declared = [set(model.shear), set(model.shift), set(model.product), set(model.linear)]
    for i, a in enumerate(declared):
        for b in declared[i + 1:]:
            if a & b:
                raise InputError(where, f"{sorted(a & b)[0]!r} has two sampling coordinates: a parameter may "
                                 f"be in at most one of shear, shift, product and linear", field="sampling")
    return model


def _forward_key(doc, where):
    """The card's ``forward`` (a function of the card contract) or ``function`` (a user's
    ``f(p, x)``: :mod:`skinfit.io.user_functions`): exactly one of them."""
    if ("forward" in doc) == ("function" in doc):
        raise InputError(where, "expected either forward = \"module:function\" (f(p, x, c) -> (y, ok)) or "
                         "function = \"module:function\" (f(p, x) -> array), not " + ("both" if "forward" in doc
                                                                                     else "neither"), field="forward")
    return require(doc, "forward" if "forward" in doc else "function", str, where)


_USER_FORWARDS = {}


def user_forward(model):
    """The forward function of a card that names a user's ``function``: found in the registry
    (role ``function``), or for a card saved in a fit imported by module and name; its source
    checked against the card's ``function_sha256`` (InputError in one line otherwise)."""
    key = (model.forward_ref, model.function_sha256, model.observable_names, model.saved, model.path)
    if key not in _USER_FORWARDS:
        if model.saved and lookup("function", model.forward_ref) is None:
            func = import_function(model.forward_ref, model.function_sha256, model.path)
        else:
            func = check_source_hash(resolve("function", model.forward_ref, model.path), model.forward_ref,
                                     model.function_sha256, model.path, model.saved)
        _USER_FORWARDS[key] = adapt(func, model.observable_names, model.forward_ref, model.path)
    return _USER_FORWARDS[key]


def function_model(cls, func, observable, covariates, parameters, id=None, title=None, source=None):
    """:meth:`Model.from_function` (which documents it): the card of ``func`` written, parsed and
    checked as a card file's is, with ``func`` registered for role ``function`` in this process."""
    ref, text = function_card(func, observable, covariates, parameters, id, title, source)
    if lookup("function", ref) is None or resolve("function", ref, "Model.from_function") is not func:
        register("function", ref, func, replace=True)
    name = getattr(func, "__name__", "?")
    digest = hashlib.sha256(text.encode("utf-8")).hexdigest()
    model = parse_model_text(text, f"model from function {name}", digest)
    return replace(model, function=adapt(func, model.observable_names, ref, model.path))


def write_card(model, folder, priors=None, overwrite=False):
    """:meth:`Model.to_card` (which documents it)."""
    folder = Path(check_path(folder, "to_card", "folder", "a folder path"))
    files = {"model": (folder / "models" / f"{model.id}.toml", model.card_text)}
    if priors is not None:
        files["priors"] = (folder / "priors" / f"{model.id}.toml", as_prior_set(priors, model, "to_card").text)
    for kind, (path, _) in files.items():
        if path.exists() and not overwrite:
            raise InputError("to_card", f"{display(path)} exists (pass overwrite=True to replace it)", field=kind)
    for path, text in files.values():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return {kind: path for kind, (path, _) in files.items()}


def _check_products(model, where):
    """``[sampling.product]``: parameter = {partner = exponent, ...}; partners are other plain
    parameters (not themselves products, sheared or shifted), exponents finite numbers."""
    special = set(model.product) | set(model.shear) | set(model.shift) | set(model.linear)
    for pname, partners in model.product.items():
        field = f"sampling.product.{pname}"
        if pname not in model.parameter_names:
            raise InputError(where, f"names unknown parameter {pname!r}", field=field)
        if not isinstance(partners, MappingProxyType) or not partners:
            raise InputError(where, f"expected {pname} = {{partner = exponent, ...}} (got {partners!r})", field=field)
        for partner, power in partners.items():
            if partner not in model.parameter_names or partner in special:
                raise InputError(where, f"partner {partner!r} must be another parameter sampled in plain log "
                                 f"(not a product, sheared, shifted or linear one)", field=field)
            if isinstance(power, bool) or not isinstance(power, (int, float)) or not math.isfinite(power):
                raise InputError(where, f"exponent of {partner!r} must be a finite number (got {power!r})",
                                 field=field)


def _derived_table(doc, where):
    """``[derived]``: function = "skinfit.physics.<module>:<function>", over = [columns],
    quantities = {name = unit}; quantities evaluated on the posterior draws of a fit."""
    table = require(doc, "derived", dict, where, default={})
    if not table:
        return MappingProxyType({})
    ref = require(table, "function", str, where, field_prefix="derived.")
    resolve("derived", ref, where)
    quantities = require(table, "quantities", dict, where, field_prefix="derived.")
    over = require(table, "over", list, where, field_prefix="derived.", default=[])
    return MappingProxyType({"function": ref, "over": tuple(over),
                             "quantities": MappingProxyType(dict(quantities))})


def list_models() -> list[str]:
    return sorted(available("models"))

