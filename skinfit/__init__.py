"""skinfit: Bayesian parameter inference for the published physics of skin friction.

>>> import skinfit
>>> model = skinfit.load_model("electroadhesion")
>>> [p.name for p in model.parameters][:2]
['E_star', 'tau0']

The public names below are imported on first use (PEP 562 ``__getattr__``), so that
``import skinfit`` and ``skinfit models`` do not import ArviZ, xarray, scipy.stats or emcee.
Everything else is internal; the layers are described in ``docs/design/layers.md``.
"""

import importlib

#: Public name -> the module that defines it (docs/api.md documents each; tests/test_public_api.py freezes them).
_PUBLIC = {
    # the files a researcher edits
    "Model": "skinfit.io.models", "load_model": "skinfit.io.models", "list_models": "skinfit.io.models",
    "PriorSet": "skinfit.io.priors", "load_priors": "skinfit.io.priors", "list_priors": "skinfit.io.priors",
    "Dataset": "skinfit.io.data", "load_dataset": "skinfit.io.data", "list_datasets": "skinfit.io.data",
    "ingest": "skinfit.report.review",
    "truncate": "skinfit.io.user_priors",
    # fitting and its result
    "fit": "skinfit.results.fitting", "Fit": "skinfit.results.fit", "load_fit": "skinfit.results.fit",
    # analyses of fits
    "evidence": "skinfit.analysis.evidence", "compare": "skinfit.analysis.compare",
    "fit_by": "skinfit.analysis.groups", "load_groups": "skinfit.analysis.groups",
    "level_contrasts": "skinfit.analysis.contrasts", "fit_contrasts": "skinfit.analysis.contrasts",
    "population": "skinfit.analysis.population.population",
    "load_population": "skinfit.analysis.population.result",
    "PopulationResult": "skinfit.analysis.population.result",
    "population_tables": "skinfit.analysis.population.population",
    "design": "skinfit.analysis.design", "run_sbc": "skinfit.analysis.sbc",
    # errors and warnings
    "InputError": "skinfit.errors", "InputTypeError": "skinfit.errors", "ForwardError": "skinfit.errors",
    "MissingDependency": "skinfit.errors", "WorkerError": "skinfit.errors",
    "ConvergenceWarning": "skinfit.errors", "SupportWarning": "skinfit.errors", "IntegrityWarning": "skinfit.errors",
    "MisfitWarning": "skinfit.inference.misfit", "RawSeriesWarning": "skinfit.inference.misfit",
    "PopulationWarning": "skinfit.analysis.population.result",
    "ShadowWarning": "skinfit.io.provenance",
}

__all__ = sorted(_PUBLIC)


def __getattr__(name):
    if name == "__version__":  # importlib.metadata costs ~0.1 s: only when asked
        from importlib.metadata import PackageNotFoundError, version

        try:
            return version("skinfit")
        except PackageNotFoundError:  # a source tree that was not installed
            return "0.0.0+unknown"
    if name not in _PUBLIC:
        raise AttributeError(f"module 'skinfit' has no attribute {name!r}")
    value = getattr(importlib.import_module(_PUBLIC[name]), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_PUBLIC))
