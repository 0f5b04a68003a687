"""Candidate measurement conditions: a TOML grid or list of points (user units), or a table of SI
covariates, checked and converted to SI."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from skinfit.errors import InputError
from skinfit.io.toml import read_toml
from skinfit.io.units import NONNEGATIVE, dimension, same_dimension, to_si

__all__ = ["convert_units", "MAX_CANDIDATES", "read_candidates", "si_candidates"]


def convert_units(values, unit, target_unit, where, field):
    """``values`` in ``unit`` -> SI, checking that ``unit`` measures what ``target_unit`` (the
    model card's) does.  Any unit the data files accept (skinfit.io.units: SI prefixes such as kN,
    uN, µN, and whatever pint reads)."""
    if not isinstance(unit, str):
        raise InputError(where, f"expected a unit text such as \"mN\" (got {unit!r})", field=field)
    try:
        factor = to_si(unit)
        same = same_dimension(unit, target_unit)
    except ValueError as exc:
        raise InputError(where, str(exc), field=field) from None
    if not same:
        raise InputError(where, f"unit {unit!r} is a {dimension(unit)}, but the model's covariate is in "
                         f"{target_unit!r} (a {dimension(target_unit)})", field=field)
    return np.asarray(values, dtype=float) * factor


#: the most candidates a design takes (its arrays grow with outer x candidates; see check_cost)
MAX_CANDIDATES = 1_000_000


_GRID_KEYS = {"unit", "values", "from", "to", "num", "log"}


def _grid_axis(spec, where, field):
    """The values (list of numbers, user unit) of one [grid.<covariate>] table."""
    if not isinstance(spec, dict):
        raise InputError(where, f"expected a table with unit and values (or from, to, num) (got {spec!r})", field=field)
    extra = sorted(set(spec) - _GRID_KEYS)
    if extra:
        raise InputError(where, f"unexpected key(s) {', '.join(extra)} (expected unit and values, or unit, from, "
                         f"to, num and optionally log)", field=field)
    if "unit" not in spec:
        raise InputError(where, "expected a unit", field=field)
    if "values" in spec:
        if {"from", "to", "num", "log"} & set(spec):
            raise InputError(where, "give values = [...] or from, to, num, not both", field=field)
        return _numbers(spec["values"], where, field + ".values")
    if not {"from", "to", "num"} <= set(spec):
        raise InputError(where, "expected values = [...] or from, to, num", field=field)
    num, log = spec["num"], spec.get("log", False)
    if isinstance(num, bool) or not isinstance(num, int) or not 1 <= num <= MAX_CANDIDATES:
        raise InputError(where, f"expected an integer from 1 to {MAX_CANDIDATES} (got {num!r})", field=field + ".num")
    if not isinstance(log, bool):
        raise InputError(where, f"expected true or false (got {log!r})", field=field + ".log")
    ends = _numbers([spec["from"], spec["to"]], where, field + ".from/to")
    if log and not (ends[0] > 0 and ends[1] > 0):
        raise InputError(where, f"log = true needs from and to > 0 (got {ends[0]:g}, {ends[1]:g})", field=field)
    return (np.geomspace if log else np.linspace)(ends[0], ends[1], num)


def read_candidates(source, model):
    """Candidate measurement conditions: (SI covariates {name: (C,)}, units {name: unit}).

    ``source``: a TOML file path, or its parsed mapping, in one of two forms::

        [grid.normal_force]            # every combination of the listed values
        unit = "mN"
        values = [200, 500, 1000]      # or: from = 200, to = 2000, num = 10 (log = true)
        [grid.voltage]
        unit = "V"
        values = [0, 100, 200]

        [units]                        # or a list of points
        normal_force = "mN"
        voltage = "V"
        [[points]]
        normal_force = 200
        voltage = 0

    Every covariate of the model must be given (optional ones may be left out); values must be
    finite and, for forces, lengths, voltages and the like, >= 0; at most
    :data:`MAX_CANDIDATES` candidates.  Units: any the data files accept (:mod:`skinfit.io.units`).
    """
    where = str(source) if not isinstance(source, dict) else "candidates"
    if isinstance(source, dict):
        doc = source
    else:
        path = Path(source)
        if not path.exists():
            raise InputError(path, "no such candidates file")
        doc, _ = read_toml(path, versioned=False)  # regular files only, bounded size and nesting, errors with the line
    cards = {c.name: c for c in model.covariates}
    columns, units = {}, {}
    if "grid" in doc and "points" in doc:
        raise InputError(where, "give either [grid.<covariate>] tables or [[points]], not both")
    extra = sorted(set(doc) - {"grid", "points", "units"})
    if extra:
        raise InputError(where, f"unexpected key(s) {', '.join(extra)} (expected [grid.<covariate>] tables, or "
                         f"[units] and [[points]])")
    if "grid" in doc:
        if not isinstance(doc["grid"], dict) or not doc["grid"]:
            raise InputError(where, "expected one [grid.<covariate>] table per covariate", field="grid")
        if "units" in doc:
            raise InputError(where, "a grid gives each covariate's unit in its own table, not under [units]",
                             field="units")
        for name, spec in doc["grid"].items():
            field = f"grid.{name}"
            if name not in cards:
                raise InputError(where, f"unknown covariate {name!r} of model {model.id!r} (covariates: "
                                 f"{', '.join(cards)})", field=field)
            columns[name] = _grid_axis(spec, where, field)
            units[name] = spec["unit"]
        size = math.prod(len(v) for v in columns.values())
        if size > MAX_CANDIDATES:
            shape = " x ".join(str(len(v)) for v in columns.values())
            raise InputError(where, f"the grid has {size:,} candidates ({shape}); at most {MAX_CANDIDATES:,}: use "
                             f"fewer values", field="grid")
        names = list(columns)
        grids = np.meshgrid(*[np.asarray(columns[k]) for k in names], indexing="ij")
        columns = {k: g.ravel() for k, g in zip(names, grids)}
    elif "points" in doc:
        units = doc.get("units", {})
        if not isinstance(units, dict):
            raise InputError(where, f"expected a table covariate = \"unit\" (got {units!r})", field="units")
        points = doc["points"]
        if not isinstance(points, list) or not points:
            raise InputError(where, "expected at least one [[points]] entry", field="points")
        if len(points) > MAX_CANDIDATES:
            raise InputError(where, f"{len(points):,} points; at most {MAX_CANDIDATES:,}", field="points")
        for i, pt in enumerate(points, 1):
            if not isinstance(pt, dict):
                raise InputError(where, f"expected a table covariate = value (got {pt!r})", field="points", row=i)
            for name in pt:
                if name not in cards:
                    raise InputError(where, f"unknown covariate {name!r} of model {model.id!r} (covariates: "
                                     f"{', '.join(cards)})", field="points", row=i)
        for name in units:
            if name not in cards:
                raise InputError(where, f"unknown covariate {name!r} of model {model.id!r}", field=f"units.{name}")
        for name in [c for c in cards if any(c in pt for pt in points)]:
            if name not in units:
                raise InputError(where, f"no unit for {name!r}: add it under [units]", field="units")
            missing = [i for i, pt in enumerate(points, 1) if name not in pt]
            if missing:
                raise InputError(where, f"covariate {name!r} missing", field="points", row=missing[0])
            columns[name] = _numbers([pt[name] for pt in points], where, f"points.{name}")
    else:
        raise InputError(where, "expected [grid.<covariate>] tables or [[points]] entries")
    fields = {name: f"grid.{name}.unit" if "grid" in doc else f"units.{name}" for name in columns}
    return _candidate_columns(columns, units, model, where, fields)


def _candidate_columns(columns, units, model, where, fields):
    """Check and convert candidate columns (user units) to SI: (X, units), optional covariates
    left out filled with NaN (missing by design)."""
    missing = [c.name for c in model.covariates if c.name not in columns and not c.optional]
    if missing:
        raise InputError(where, f"no candidate values for covariate(s) {', '.join(missing)} of model "
                         f"{model.id!r}")
    cards = {c.name: c for c in model.covariates}
    X = {}
    for name, values in columns.items():
        X[name] = convert_units(values, units[name], cards[name].unit, where, fields[name])
        if dimension(units[name]) in NONNEGATIVE and (X[name] < 0).any():
            raise InputError(where, f"{name} must be >= 0 (got {float(np.min(values)):g} {units[name]})",
                             field=fields[name])
    size = len(next(iter(X.values())))
    for c in model.covariates:
        if c.name not in X:  # optional covariate left out: missing by design
            X[c.name] = np.full(size, np.nan)
    return X, dict(units)


def si_candidates(table, model):
    """Candidates given as a mapping (or DataFrame) covariate -> SI values: checked as a file's."""
    cards = {c.name: c for c in model.covariates}
    columns = {}
    for name, values in dict(table).items():
        if name not in cards:
            raise InputError("candidates", f"unknown covariate {name!r} of model {model.id!r} (covariates: "
                             f"{', '.join(cards)})", field=str(name))
        values = np.asarray(values, dtype=object).ravel().tolist()
        if len(values) > MAX_CANDIDATES:
            raise InputError("candidates", f"{len(values):,} candidates; at most {MAX_CANDIDATES:,}", field=name)
        columns[name] = _numbers(values, "candidates", name, allow_nan=cards[name].optional)
    sizes = {len(v) for v in columns.values()}
    if len(sizes) > 1:
        raise InputError("candidates", f"the covariates have different lengths "
                         f"({', '.join(f'{k}: {len(v)}' for k, v in columns.items())})")
    return _candidate_columns(columns, {k: cards[k].unit for k in columns}, model, "candidates",
                              {k: k for k in columns})


def _numbers(raw, where, field, allow_nan=False):
    if not isinstance(raw, list) or not raw:
        raise InputError(where, f"expected a non-empty list of numbers (got {raw!r})", field=field)
    for i, v in enumerate(raw, 1):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)) or \
                not (math.isfinite(v) or (allow_nan and math.isnan(v))):
            raise InputError(where, f"expected a finite number (got {v!r})", field=field, row=i)
    return np.asarray(raw, dtype=float)
