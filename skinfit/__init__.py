"""skinfit: Bayesian parameter inference for the published physics of skin friction.

>>> import skinfit
>>> model = skinfit.load_model("electroadhesion")
>>> [p.name for p in model.parameters][:2]
['E_star', 'tau0']
"""

from importlib.metadata import PackageNotFoundError, version

from .compare import compare
from .data import Dataset, list_datasets, load_dataset
from .design import design
from .errors import ConvergenceWarning, InputError, SupportWarning
from .evidence import evidence
from .fit import Fit, fit, load_fit
from .models import Model, list_models, load_model
from .priors import PriorSet, list_priors, load_priors

try:
    __version__ = version("skinfit")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

__all__ = [
    "ConvergenceWarning",
    "Dataset",
    "Fit",
    "InputError",
    "Model",
    "PriorSet",
    "SupportWarning",
    "compare",
    "design",
    "evidence",
    "fit",
    "list_datasets",
    "list_models",
    "list_priors",
    "load_dataset",
    "load_fit",
    "load_model",
    "load_priors",
]
