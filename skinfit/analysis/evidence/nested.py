"""log Z by dynesty's nested sampling (optional dependency: the ``nested`` extra), an
independent check of the other estimators."""

import time

import numpy as np

from skinfit.analysis.evidence.log_evidence import LogEvidence
from skinfit.errors import require_optional

__all__ = ["nested"]


def nested(loglike, prior_transform, ndim, *, rng, nlive=400, sample="rslice", dlogz=0.05, **options):
    """log Z by dynesty's static nested sampler (Speagle 2020), ``rslice`` by default.

    ``loglike(theta)`` is the full log likelihood (all constants) of one parameter vector and
    ``prior_transform(u)`` maps the unit cube to the (normalised) prior. The standard error is
    dynesty's own ``logzerr``.
    """
    dynesty = require_optional("dynesty", "nested")  # an optional dependency: imported here, when used
    t0 = time.perf_counter()

    def finite_loglike(theta):
        value = loglike(theta)
        return value if np.isfinite(value) else -1e300  # outside the support: zero likelihood

    sampler = dynesty.NestedSampler(finite_loglike, prior_transform, ndim, nlive=nlive, sample=sample,
                                    rstate=rng, **options)
    sampler.run_nested(dlogz=dlogz, print_progress=False)
    res = sampler.results
    return LogEvidence(log_z=float(res.logz[-1]), se=float(res.logzerr[-1]), method="nested",
                       n_evals=int(np.sum(res.ncall)), seconds=time.perf_counter() - t0,
                       details={"nlive": nlive, "sample": sample, "dlogz": dlogz, "iterations": int(res.niter)})
