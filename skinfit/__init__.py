"""skinfit: Bayesian parameter inference for the published physics of skin friction.

>>> import skinfit
>>> model = skinfit.load_model("electroadhesion")
>>> [p.name for p in model.parameters][:2]
['E_star', 'tau0']

The public names are imported on first use (PEP 562), so ``import skinfit`` and commands
such as ``skinfit models`` do not pay for ArviZ, xarray, scipy.stats or emcee (several
seconds on a loaded 2-core machine; bench/results/startup.md).
"""

import importlib
import importlib.util
import sys
import types

#: Public name -> the submodule that defines it.
_LAZY = {
    "ConvergenceWarning": "errors", "InputError": "errors", "SupportWarning": "errors",
    "Dataset": "data", "list_datasets": "data", "load_dataset": "data",
    "Model": "models", "list_models": "models", "load_model": "models",
    "PriorSet": "priors", "list_priors": "priors", "load_priors": "priors",
    "Fit": "fit", "fit": "fit", "load_fit": "fit",
    "evidence": "evidence", "compare": "compare", "design": "design",
}

__all__ = sorted(_LAZY)
_SHADOWED = ("fit", "compare", "evidence", "design")  # functions named like their submodules


class _Package(types.ModuleType):
    """The package module: public names resolved on first use.

    ``skinfit.fit``, ``skinfit.compare`` and ``skinfit.evidence`` are functions named like
    their submodules; importing a submodule sets the package attribute of that name, which
    here would hide the function, so that assignment is skipped (``sys.modules`` still holds
    the submodule, and ``from skinfit.results.fit import ...`` works as before).
    """

    def __getattr__(self, name):
        if name == "__version__":  # importlib.metadata costs ~0.1 s: only when asked
            from importlib.metadata import PackageNotFoundError, version

            try:
                value = version("skinfit")
            except PackageNotFoundError:  # running from a source tree without installation
                value = "0.0.0+unknown"
            super().__setattr__(name, value)
            return value
        if name not in _LAZY:  # a submodule (skinfit._toml, skinfit.plots...), as eager imports gave
            if name.startswith("__") or importlib.util.find_spec(f"{__name__}.{name}") is None:
                raise AttributeError(f"module 'skinfit' has no attribute {name!r}")
            return importlib.import_module(f".{name}", __name__)
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        super().__setattr__(name, value)
        return value

    def __setattr__(self, name, value):
        if name in _SHADOWED and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)

    def __dir__(self):
        return sorted(set(super().__dir__()) | set(_LAZY))


sys.modules[__name__].__class__ = _Package
