"""Estimators of the log marginal likelihood (log evidence), independent of skin physics.

Every estimator takes a *normalised* log target: log likelihood with all its constants plus a
proper, normalised log prior (and the Jacobian of any change of coordinates), so that the
returned ``log Z`` is comparable between models on the same data.

- :func:`bridge_sampling` -- Meng & Wong (1996) iterative bridge sampling with a multivariate
  normal proposal fitted on half of the posterior draws; relative mean-squared error of
  Fruehwirth-Schnatter (2004) as used by Gronau et al. (2017), with the posterior half's
  autocorrelation accounted for through its effective sample size.
- :func:`laplace` -- Laplace's approximation at the mode with a central-difference Hessian
  (exact for a Gaussian posterior; flagged as approximate).
- :func:`nested` -- dynesty's nested sampling (optional dependency) as an independent check.

Never the naive harmonic mean: on the test problems of ``NOTES.md`` it was off by 5-8 nats.
"""

import math
import time
from dataclasses import dataclass, field

import numpy as np

__all__ = ["LogEvidence", "bridge_sampling", "laplace", "nested", "bayes_factor_strength"]


@dataclass(frozen=True)
class LogEvidence:
    """A log marginal likelihood estimate.

    Attributes
    ----------
    log_z : float
        Natural log of the evidence.
    se : float
        Its standard error (NaN for Laplace, whose error is not estimable from one expansion).
    method : str
        ``"bridge"``, ``"laplace"`` or ``"nested"``.
    n_evals : int
        Log-target (or log-likelihood) evaluations spent on the estimate.
    seconds : float
        Wall time.
    approximate : bool
        True when the estimate carries an unquantified approximation error (Laplace).
    repeats : tuple of float
        Individual estimates when the estimate was repeated.
    details : dict
        Method-specific figures (iterations, proposal, relative MSE, ...).
    """

    log_z: float
    se: float
    method: str
    n_evals: int
    seconds: float
    approximate: bool = False
    repeats: tuple = ()
    details: dict = field(default_factory=dict, compare=False)

    def __str__(self):
        se = "n/a" if math.isnan(self.se) else f"{self.se:.3f}"
        tag = ", approximate" if self.approximate else ""
        return f"log Z = {self.log_z:.3f} +- {se} ({self.method}{tag}, {self.n_evals} evaluations)"


# ---- bridge sampling ---------------------------------------------------------------------

def bridge_sampling(log_target, samples, *, rng, n_repeats=1, ess=None, tol=1e-10, max_iter=1000):
    """log Z by iterative bridge sampling (Meng & Wong 1996; Gronau et al. 2017).

    Parameters
    ----------
    log_target : callable
        ``log_target(z)`` for ``z`` of shape (k, d) returns the normalised log posterior kernel
        (log likelihood + log prior + log Jacobian), shape (k,); ``-inf`` outside the support.
    samples : array, shape (n, d)
        Posterior draws in the same coordinates (unbounded coordinates work best).
    rng : numpy.random.Generator
        Source of the random split and of the proposal draws.
    n_repeats : int
        Independent repetitions (fresh split and proposal draws). The reported ``log_z`` is
        their mean, ``se`` the larger of the error formula and the repetitions' spread.
    ess : float, optional
        Effective sample size of ``samples`` (default: ``n``, i.e. independent draws).
    """
    samples = np.asarray(samples, dtype=float)
    if samples.ndim != 2 or len(samples) < 4 * samples.shape[1] + 8:
        raise ValueError(f"bridge sampling needs a (n, d) array of posterior draws with n >= 4*d + 8 "
                         f"(got shape {samples.shape})")
    if not np.all(np.isfinite(samples)):
        raise ValueError("bridge sampling: posterior draws contain non-finite values")
    t0 = time.perf_counter()
    n = len(samples)
    ess_fraction = 1.0 if ess is None else float(np.clip(ess / n, 1e-3, 1.0))
    runs = [_bridge_once(log_target, samples, rng, ess_fraction, tol, max_iter) for _ in range(n_repeats)]
    estimates = np.array([r["log_z"] for r in runs])
    se_formula = float(np.sqrt(np.mean([r["re2"] for r in runs])))
    spread = float(np.std(estimates, ddof=1)) if n_repeats > 1 else 0.0
    details = {"relative_mse": float(np.mean([r["re2"] for r in runs])), "se_formula": se_formula,
               "se_repeats": spread if n_repeats > 1 else None, "iterations": [r["iterations"] for r in runs],
               "n_proposal": runs[0]["n2"], "n_posterior_fit": runs[0]["n_fit"], "ess_fraction": ess_fraction,
               "proposal": "multivariate normal fitted on half of the draws"}
    return LogEvidence(log_z=float(np.mean(estimates)), se=max(se_formula, spread), method="bridge",
                       n_evals=int(sum(r["n_evals"] for r in runs)), seconds=time.perf_counter() - t0,
                       repeats=tuple(float(e) for e in estimates) if n_repeats > 1 else (), details=details)


def _bridge_once(log_target, samples, rng, ess_fraction, tol, max_iter):
    from scipy.special import logsumexp  # here, not with the module: comparing cached evidence needs no scipy

    n, d = samples.shape
    order = rng.permutation(n)
    fit_half, est_half = samples[order[: n // 2]], samples[order[n // 2:]]
    mean = fit_half.mean(axis=0)
    cov = np.atleast_2d(np.cov(fit_half, rowvar=False))
    chol = np.linalg.cholesky(cov + 1e-12 * np.diag(np.diag(cov)))
    n1 = len(est_half)
    n2 = n1
    proposal = mean + rng.standard_normal((n2, d)) @ chol.T
    log_g = _mvn_logpdf(mean, chol)

    q11 = np.asarray(log_target(est_half), dtype=float)  # target at posterior draws
    q12 = log_g(est_half)                                # proposal at posterior draws
    q21 = np.asarray(log_target(proposal), dtype=float)  # target at proposal draws
    q22 = log_g(proposal)                                # proposal at proposal draws
    if not np.all(np.isfinite(q11)):
        raise ValueError("bridge sampling: the log target is not finite at some posterior draws")
    if np.any(np.isnan(q21)):
        raise ValueError("bridge sampling: the log target is NaN at some proposal draws")

    l1, l2 = q11 - q12, q21 - q22  # log ratios target/proposal
    n1_eff = max(ess_fraction * n1, 2.0)
    s1, s2 = n1_eff / (n1_eff + n2), n2 / (n1_eff + n2)
    log_s1, log_s2 = math.log(s1), math.log(s2)
    log_r = float(np.median(l1))  # start (any positive value converges; this one is close)
    for iteration in range(1, max_iter + 1):
        num = logsumexp(l2 - np.logaddexp(log_s1 + l2, log_s2 + log_r)) - math.log(n2)
        den = logsumexp(-np.logaddexp(log_s1 + l1, log_s2 + log_r)) - math.log(n1)
        new = float(num - den)
        if abs(new - log_r) < tol:
            log_r = new
            break
        log_r = new
    else:
        raise RuntimeError(f"bridge sampling did not converge in {max_iter} iterations")

    # relative mean-squared error of Z (Fruehwirth-Schnatter 2004; Gronau et al. 2017, eq. 17)
    f1 = np.exp(l2 - log_r - np.logaddexp(log_s1 + l2 - log_r, log_s2))  # at proposal draws
    f2 = np.exp(-np.logaddexp(log_s1 + l1 - log_r, log_s2))              # at posterior draws
    re2 = np.var(f1, ddof=1) / np.mean(f1) ** 2 / n2 + np.var(f2, ddof=1) / np.mean(f2) ** 2 / n1_eff
    return {"log_z": log_r, "re2": float(re2), "iterations": iteration, "n_evals": n1 + n2, "n2": n2,
            "n_fit": len(fit_half)}


def _mvn_logpdf(mean, chol):
    d = len(mean)
    log_det = 2.0 * np.sum(np.log(np.diag(chol)))
    const = -0.5 * (d * math.log(2 * math.pi) + log_det)

    def log_g(z):
        w = np.linalg.solve(chol, (np.asarray(z) - mean).T)
        return const - 0.5 * np.sum(w**2, axis=0)

    return log_g


# ---- Laplace -----------------------------------------------------------------------------

def laplace(log_target, start, *, rel_step=0.1, max_newton=20):
    """log Z by Laplace's approximation: log p(mode) + d/2 log 2 pi - 1/2 log det H.

    The mode is refined from ``start`` (e.g. the MAP, which in other coordinates is not the
    mode of this target) by damped Newton steps; ``H`` is minus the Hessian of ``log_target``
    there by central differences with steps of ``rel_step`` posterior standard deviations, all
    stencil points evaluated in one vectorised call. Exact when the log target is quadratic.
    """
    t0 = time.perf_counter()
    x = np.asarray(start, dtype=float)
    f = float(np.asarray(log_target(x[None]))[0])
    if not np.isfinite(f):
        raise ValueError("Laplace: the log target is not finite at the starting point (the MAP)")
    h = 1e-3 * np.maximum(1.0, np.abs(x))
    n_evals = 1
    for _ in range(max_newton):
        H, g, used = _derivatives(log_target, x, f, h)
        n_evals += used
        if np.all(np.diag(H) > 0):
            h = rel_step / np.sqrt(np.diag(H))
        try:
            step = np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            break
        for damping in (1.0, 0.5, 0.25, 0.125):
            trial = x + damping * step
            f_trial = float(np.asarray(log_target(trial[None]))[0])
            n_evals += 1
            if np.isfinite(f_trial) and f_trial >= f:
                break
        else:
            break
        x, f_old, f = trial, f, f_trial
        if f - f_old < 1e-10:
            break
    H, _, used = _derivatives(log_target, x, f, h)
    n_evals += used
    try:
        chol = np.linalg.cholesky(H)
    except np.linalg.LinAlgError:
        raise ValueError("Laplace: the negative Hessian at the mode is not positive definite "
                         "(no maximum: a flat or curved-away direction, or a mode on a bound)") from None
    log_det = 2.0 * np.sum(np.log(np.diag(chol)))
    log_z = f + 0.5 * len(x) * math.log(2 * math.pi) - 0.5 * log_det
    return LogEvidence(log_z=float(log_z), se=float("nan"), method="laplace", n_evals=n_evals,
                       seconds=time.perf_counter() - t0, approximate=True,
                       details={"log_target_at_mode": f, "log_det_neg_hessian": float(log_det),
                                "mode": x.tolist(), "step": h.tolist()})


def _derivatives(log_target, x0, f0, h):
    """Minus the Hessian and the gradient by central differences (2d^2 points, one call)."""
    d = len(x0)
    e = np.diag(h)
    points = [x0 + e[i] for i in range(d)] + [x0 - e[i] for i in range(d)]
    pairs = [(i, j) for i in range(d) for j in range(i + 1, d)]
    for i, j in pairs:
        points += [x0 + e[i] + e[j], x0 + e[i] - e[j], x0 - e[i] + e[j], x0 - e[i] - e[j]]
    f = np.asarray(log_target(np.array(points)), dtype=float)
    if not np.all(np.isfinite(f)):
        raise ValueError("Laplace: the log target is not finite next to the mode (a bound or the "
                         "edge of the physical support is within the finite-difference step)")
    fp, fm = f[:d], f[d:2 * d]
    H = np.empty((d, d))
    H[np.diag_indices(d)] = -(fp - 2 * f0 + fm) / h**2
    for k, (i, j) in enumerate(pairs):
        a, b, c, g = f[2 * d + 4 * k: 2 * d + 4 * k + 4]
        H[i, j] = H[j, i] = -(a - b - c + g) / (4 * h[i] * h[j])
    return H, (fp - fm) / (2 * h), len(points)


# ---- nested sampling ---------------------------------------------------------------------

def nested(loglike, prior_transform, ndim, *, rng, nlive=400, sample="rslice", dlogz=0.05, **options):
    """log Z by dynesty's static nested sampler (Speagle 2020), ``rslice`` by default.

    ``loglike(theta)`` is the full log likelihood (all constants) of one parameter vector and
    ``prior_transform(u)`` maps the unit cube to the (normalised) prior. The standard error is
    dynesty's own ``logzerr``.
    """
    from .errors import require_optional

    dynesty = require_optional("dynesty", "nested")
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


# ---- words -------------------------------------------------------------------------------

def bayes_factor_strength(log_bf):
    """Kass & Raftery (1995) words for a Bayes factor given as ``ln BF`` (>= 0 favours the first).

    On 2 ln BF: 0-2 "not worth more than a bare mention", 2-6 "positive", 6-10 "strong",
    > 10 "very strong".
    """
    two = 2.0 * abs(float(log_bf))
    if two < 2:
        return "not worth more than a bare mention"
    if two < 6:
        return "positive"
    if two < 10:
        return "strong"
    return "very strong"
