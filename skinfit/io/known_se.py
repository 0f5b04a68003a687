"""Per-row standard errors a dataset states for its measurements: columns ``<name>_se``.

A per-stroke dataset (``skinfit ingest``, or a lab's own table of means) knows how precisely
each row's mean was measured: the standard error of the mean from the within-stroke scatter.
For an observable ``y`` a column ``y_se`` (same dimension as ``y``, finite, >= 0, on every row)
enters the likelihood as a known variance added to the noise's (:class:`skinfit.Posterior`):
``y_i ~ N(f(x_i), sigma^2 + se_i^2)``, sigma then the extra row-to-row scatter
(docs/known-standard-errors.md).  For a covariate ``x`` a column ``x_se`` is only reported:
the covariate is treated as known (errors-in-variables are not modelled), with its largest
relative standard error so that a reader can judge whether that matters.
"""

import numpy as np

from skinfit.errors import InputError
from skinfit.io.units import parse_unit

__all__ = ["SE_SUFFIX", "se_column", "observable_se", "covariate_se"]

#: Suffix of a standard-error column: ``tangential_force_se`` is the se of ``tangential_force``.
SE_SUFFIX = "_se"


def se_column(name):
    """The name of the standard-error column of quantity ``name``."""
    return name + SE_SUFFIX


def _header(dataset, name):
    try:
        return dataset.column(name).header
    except KeyError:
        return name


def _checked(dataset, name, unit, what):
    """The SI values (n,) of ``dataset``'s column ``<name>_se``: a quantity whose unit has the
    dimension of ``unit`` (the model card's unit of ``name``), a finite number >= 0 on every row;
    InputError naming the file, column and row otherwise."""
    col = se_column(name)
    field = f"column {_header(dataset, col)!r}"
    try:
        spec = dataset.column(col)
    except KeyError:
        spec = None
    expected = parse_unit(unit)
    if spec is None or spec.kind != "quantity" or not spec.unit:
        raise InputError(dataset.path, f"is the standard error of {what} {name!r} and needs a unit of "
                         f"{expected.name} (e.g. {unit}): write '{col} [{unit}]' in the header or give its unit "
                         "in the dataset card", field=field)
    got = parse_unit(spec.unit)
    if got.dims != expected.dims:
        raise InputError(dataset.path, f"unit {spec.unit!r} is a {got.name}; the standard error of {what} "
                         f"{name!r} must be a {expected.name} like {name} itself (e.g. {unit})", field=field)
    values = dataset.frame[col].to_numpy(dtype=float)
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.argmax(bad))
        raise InputError(dataset.path, f"missing or non-finite standard error (expected a number >= 0 in "
                         f"{spec.unit} on every row; got {values[row]:g})", field=field, row=row + 1)
    if (values < 0).any():
        row = int(np.argmax(values < 0))
        raise InputError(dataset.path, f"expected a standard error >= 0 (got {values[row] / got.factor:g} "
                         f"{spec.unit})", field=field, row=row + 1)
    return values


def observable_se(dataset, model, observables):
    """observable -> its per-row standard errors, SI (n,), for each of ``observables`` whose
    column ``<observable>_se`` ``dataset`` has (checked: :func:`_checked`); empty when none."""
    units = {q.name: q.unit for q in model.observables}
    return {o: _checked(dataset, o, units[o], "observable") for o in observables
            if se_column(o) in dataset.frame.columns}


def covariate_se(dataset, model):
    """covariate -> {column, max_relative, row}: the covariates of ``model`` whose column
    ``<covariate>_se`` ``dataset`` has (checked like an observable's), with their largest
    relative standard error se_i / |x_i| over the rows where x_i != 0 and its 1-based row
    (``max_relative`` None when x is 0 or missing on every row).  Reported, not modelled."""
    out = {}
    frame = dataset.frame
    for cov in model.covariates:
        if se_column(cov.name) not in frame.columns or cov.name not in frame.columns:
            continue
        se = _checked(dataset, cov.name, cov.unit, "covariate")
        x = np.abs(frame[cov.name].to_numpy(dtype=float))
        ok = np.isfinite(x) & (x > 0)
        rel = np.where(ok, se / np.where(ok, x, 1.0), -np.inf)
        row = int(np.argmax(rel))
        out[cov.name] = {"column": se_column(cov.name), "max_relative": float(rel[row]) if ok.any() else None,
                         "row": row + 1 if ok.any() else None}
    return out
