"""``skinfit.evidence``: the log marginal likelihood of a fit, with an honest error.

Wires the model-agnostic estimators of :mod:`skinfit.analysis.evidence` to a fit's own
posterior: the log-target is the fit's normalised log posterior in its sampling coordinates
(likelihood with all its constants, priors renormalised over their bounds, Jacobian of the
coordinate map), so numbers from different models on the same data are comparable.
Results are cached in the fit's attributes (``attrs["evidence"]``) and saved with it.
"""

from __future__ import annotations

import inspect
import json
import time

import numpy as np

from skinfit.analysis.evidence.bridge import bridge_sampling
from skinfit.analysis.evidence.laplace import LaplaceError, laplace
from skinfit.analysis.evidence.log_evidence import LogEvidence
from skinfit.analysis.evidence.nested import nested
from skinfit.errors import InputError
from skinfit.io.arguments import as_generator, check_count, check_flag, check_seed
from skinfit.results.fit import Fit, as_fit
from skinfit.results.pointwise import theta_of

__all__ = ["evidence", "posterior_draws", "METHODS"]


METHODS = ("bridge", "laplace", "nested")


_ESTIMATORS = {"bridge": bridge_sampling, "laplace": laplace}


#: Most repeats of one estimate (each is a whole estimate; their spread is the error's check).
MAX_REPEATS = 10_000


def posterior_draws(fit):
    """Posterior draws of every sampled slot, natural units, shape (n_draws, d), slot order
    (:func:`skinfit.results.pointwise.theta_of` of the fit's ``posterior`` group)."""
    return theta_of(fit.posterior, fit.group("posterior"))


def evidence(fit: Fit, method: str = "bridge", *, rng: int | np.random.Generator | None = None,
             n_repeats: int = 1, refresh: bool = False, **options) -> LogEvidence:
    """log Z of ``fit`` by ``method`` ("bridge" default, "laplace", "nested").

    Returns a :class:`~skinfit.analysis.evidence.LogEvidence` (``log_z``, ``se``, ``caveat``, ...).
    ``n_repeats`` > 1 repeats the estimate with fresh random splits and reports the spread.
    The result is stored in ``fit.attrs["evidence"]`` (save the fit to keep it).

    Laplace integrates its Gaussian over the prior bounds (a posterior a bound cuts keeps only
    the mass inside) and is checked against the fit's posterior draws, which bound log Z from
    both sides (its ``caveat`` gives the bracket); where a Gaussian cannot describe the
    posterior it raises :class:`~skinfit.InputError` in one line naming why.
    """
    fit = as_fit(fit, "evidence", "fit")
    if method not in METHODS:
        raise InputError("evidence", f"unknown evidence method {method!r} (expected one of {', '.join(METHODS)})",
                         field="method")
    check_seed(rng, "evidence")
    n_repeats = check_count(n_repeats, "evidence", "n_repeats", hi=MAX_REPEATS)
    refresh = check_flag(refresh, "evidence", "refresh")
    if method != "nested":  # nested passes its options on to dynesty, which names an unknown one itself
        known = [n for n, p in inspect.signature(_ESTIMATORS[method]).parameters.items()
                 if p.kind is p.KEYWORD_ONLY and n not in ("rng", "n_repeats", "ess")]
        unknown = sorted(set(options) - set(known))
        if unknown:
            raise InputError("evidence", f"unknown option(s) {', '.join(unknown)} of method {method!r} (options: "
                                         f"{', '.join(known)})", field="options")
    cache = json.loads(fit.attrs.get("evidence", "{}"))
    if (method in cache and not refresh and cache[method].get("n_repeats", 1) >= n_repeats
            and (method != "laplace" or "caveat" in cache[method])):  # an unchecked Laplace value is redone
        return _from_dict(cache[method])
    rng = as_generator(rng if rng is not None else _seed_for(fit, method))
    post = fit.posterior
    t0 = time.perf_counter()
    if method == "bridge":
        z = post.to_z(posterior_draws(fit))
        ess = _ess_of(fit)
        result = bridge_sampling(post, z, rng=rng, n_repeats=n_repeats, ess=ess, **options)
    elif method == "laplace":
        z_map = post.to_z(np.array([[fit.map[n] for n in post.names]]))[0]
        lower, upper = post.box_bounds()
        try:
            result = laplace(post, z_map, lower=lower, upper=upper, draws=post.to_z(posterior_draws(fit)),
                             ess=_ess_of(fit), rng=rng, names=post.names, **options)
        except LaplaceError as err:
            raise InputError(f"evidence of {fit.model_id} on {fit.dataset_id}",
                             f"{err}; use method='bridge' (the default)", field="method=laplace") from None
    else:
        def loglike(theta):
            return float(post.log_likelihood(np.asarray(theta)[None])[0])

        def prior_transform(u):
            return post.prior_transform(np.asarray(u)[None])[0]

        result = nested(loglike, prior_transform, post.ndim, rng=rng, **options)
    record = _to_dict(result)
    record["n_repeats"] = n_repeats
    record["wall_s"] = time.perf_counter() - t0
    cache[method] = record
    fit.attrs["evidence"] = json.dumps(cache)
    return result


def _ess_of(fit):
    """Effective sample size of the stored draws (min over parameters, emcee estimate)."""
    sampler = fit.attr("sampler")
    sizes = fit.group("posterior").sizes
    n_draws = sizes["chain"] * sizes["draw"]
    ess = min(sampler["ess_emcee"].values())
    return float(min(ess, n_draws))


def _seed_for(fit, method):
    seed = int(fit.attrs.get("seed", -1))
    return np.random.SeedSequence([max(seed, 0), METHODS.index(method), 7919]).generate_state(1)[0]


def _to_dict(result):
    return {"log_z": result.log_z, "se": result.se, "method": result.method, "n_evals": result.n_evals,
            "seconds": result.seconds, "approximate": result.approximate, "repeats": list(result.repeats),
            "caveat": result.caveat}


def _from_dict(d):
    return LogEvidence(log_z=d["log_z"], se=d["se"], method=d["method"], n_evals=d["n_evals"],
                       seconds=d["seconds"], approximate=d["approximate"], repeats=tuple(d.get("repeats", ())),
                       caveat=d.get("caveat", ""))
