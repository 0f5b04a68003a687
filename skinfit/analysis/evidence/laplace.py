"""log Z by Laplace's approximation at the mode with a central-difference Hessian, its Gaussian
integrated over the prior bounds (exact for a Gaussian posterior, truncated or not; flagged as
approximate, and checked against posterior draws when given)."""

import math
import time

import numpy as np
from scipy import special, stats

from skinfit.analysis.evidence.bridge import mvn_logpdf
from skinfit.analysis.evidence.log_evidence import LogEvidence

__all__ = ["LaplaceError", "laplace"]


class LaplaceError(ValueError):
    """Laplace's approximation does not apply to this log target; the message says why."""


def laplace(log_target, start, *, lower=None, upper=None, draws=None, ess=None, rng=None, names=None,
            rel_step=0.1, max_newton=20, n_check=2000):
    """log Z by Laplace's approximation, its Gaussian integrated over the box of bounds only.

    The log target is expanded to second order at a point ``x`` near its mode,
    ``f(x) + g.u - u.H.u / 2``, and that exponential is integrated over the box
    ``[lower, upper]`` (the prior bounds in the sampling coordinates):

        log Z ~ f(x) + g.H^-1.g / 2 + d/2 log(2 pi) - 1/2 log det H + log P,

    ``P`` the mass of N(x + H^-1 g, H^-1) inside the box (1 for an interior mode; a posterior that
    a bound cuts keeps only the mass inside).  Exact when the log target is quadratic inside the
    box.  ``x`` is refined from ``start`` (e.g. the MAP) by damped Newton steps kept one and a
    half finite-difference steps inside the box; ``H`` and ``g`` are minus the Hessian and the
    gradient by central differences of ``rel_step`` standard deviations of the Gaussian (the
    first of ``rel_step`` standard deviations of ``draws`` when given), every stencil point in
    one vectorised call.

    With ``draws`` (posterior draws, (n, d), effective sample size ``ess``) and ``rng``, the
    Gaussian ``q`` (truncated to the box and to where the target is finite) is checked against
    the posterior: ``E_q[log target - log q] <= log Z <= E_post[log target - log q]`` (the
    evidence lower and upper bounds, each from at most ``n_check`` draws; their gap is the sum
    of the two Kullback-Leibler divergences between q and the posterior).  A Laplace value
    outside that bracket (by more than three Monte Carlo errors and 0.02 nats) is refused;
    otherwise the bracket is reported in the caveat, however wide.

    Raises :class:`LaplaceError` (one line naming the coordinate, from ``names``) when there is
    no maximum (a flat or curved-away direction), the target is not finite next to the mode
    inside the box, or the Gaussian contradicts the draws.
    """
    t0 = time.perf_counter()
    x = np.asarray(start, dtype=float).copy()
    d = len(x)
    names = list(names) if names is not None else [f"coordinate {i}" for i in range(d)]
    lo = np.full(d, -np.inf) if lower is None else np.asarray(lower, dtype=float)
    hi = np.full(d, np.inf) if upper is None else np.asarray(upper, dtype=float)
    scale = None
    if draws is not None:
        draws = np.asarray(draws, dtype=float)
        scale = np.std(draws, axis=0, ddof=1)
        if not np.all(np.isfinite(scale) & (scale > 0)):
            flat = names[int(np.argmin(np.where(np.isfinite(scale), scale, -1.0)))]
            raise LaplaceError(f"Laplace: the posterior draws do not vary along {flat}")
    h = rel_step * scale if scale is not None else 1e-3 * np.maximum(1.0, np.abs(x))
    h = np.minimum(h, (hi - lo) / 4)  # a stencil fits inside the box

    def inside(z, step):  # kept 1.5 steps from every bound, so the stencil stays inside the box
        return np.clip(z, lo + 1.5 * step, hi - 1.5 * step)

    def value(z):
        return float(np.asarray(log_target(z[None]), dtype=float)[0])

    x = inside(x, h)
    f = value(x)
    if not np.isfinite(f):
        raise LaplaceError("Laplace: the log target is not finite at the starting point (the MAP)")
    n_evals = 1
    for _ in range(max_newton):
        H, g, used = _derivatives(log_target, x, f, h, names)
        n_evals += used
        if np.all(np.diag(H) > 0):
            h = np.minimum(rel_step / np.sqrt(np.diag(H)), (hi - lo) / 4)
        try:
            step = np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            break
        for damping in (1.0, 0.5, 0.25, 0.125):
            trial = inside(x + damping * step, h)
            f_trial = value(trial)
            n_evals += 1
            if np.isfinite(f_trial) and f_trial >= f:
                break
        else:
            break
        x, f_old, f = trial, f, f_trial
        if f - f_old < 1e-10:
            break
    x = inside(x, h)
    f = value(x)
    H, g, used = _derivatives(log_target, x, f, h, names)
    n_evals += used + 1
    eigval, eigvec = np.linalg.eigh(0.5 * (H + H.T))
    if eigval[0] <= 0:
        along = names[int(np.argmax(np.abs(eigvec[:, 0])))]
        raise LaplaceError(f"Laplace: no maximum near the MAP (the log target is flat or curves upward "
                           f"along {along}): a Gaussian cannot describe this posterior")
    cov = (eigvec / eigval) @ eigvec.T
    mean = x + cov @ g
    log_det = float(np.sum(np.log(eigval)))
    log_mass, cut = _log_box_mass(mean, cov, lo, hi, rng)
    if not np.isfinite(log_mass):
        raise LaplaceError(f"Laplace: the Gaussian at the mode has no mass inside the prior bounds of "
                           f"{', '.join(names[i] for i in cut)}")
    log_z = f + 0.5 * g @ cov @ g + 0.5 * d * math.log(2 * math.pi) + 0.5 * (-log_det) + log_mass
    details = {"log_target_at_mode": f, "log_det_neg_hessian": log_det, "mode": x.tolist(),
               "step": h.tolist(), "gaussian_mean": mean.tolist(), "log_mass_inside_bounds": log_mass,
               "cut_by_bounds": [names[i] for i in cut]}
    caveats = []
    if cut and log_mass < math.log(0.99):
        caveats.append(f"the Gaussian at the mode reaches past the prior bounds of {', '.join(names[i] for i in cut)} "
                       f"and is integrated inside them only ({math.exp(log_mass):.3g} of its mass)")
    if draws is not None and rng is not None and n_check > 0:
        check, used = _bracket(log_target, draws, ess, rng, mean, cov, lo, hi, log_mass, n_check)
        n_evals += used
        details.update(check)
        log_z += check["log_mass_in_support"]
        if check["log_mass_in_support"] < 0:
            caveats.append(f"{1 - math.exp(check['log_mass_in_support']):.2g} of its mass lies where the posterior "
                           f"is zero (a bound that depends on other parameters, or the model's support) and is "
                           f"left out (+-{check['log_mass_in_support_se']:.2g} nats, from "
                           f"{check['n_gaussian_draws']} draws)")
        low, high = check["elbo"], check["eubo"]
        slack_low, slack_high = 3 * check["elbo_se"] + 0.02, 3 * check["eubo_se"] + 0.02
        if not (low - slack_low <= log_z <= high + slack_high):
            raise LaplaceError(f"Laplace: its Gaussian does not describe this posterior: the posterior draws "
                               f"bound log Z within [{low:.2f}, {high:.2f}], the Laplace value {log_z:.2f} "
                               "lies outside")
        caveats.append(f"the posterior draws bound log Z within [{low:.2f}, {high:.2f}]")
    else:
        caveats.append("not checked against posterior draws")
    return LogEvidence(log_z=float(log_z), se=float("nan"), method="laplace", n_evals=n_evals,
                       seconds=time.perf_counter() - t0, approximate=True,
                       caveat="approximate: " + "; ".join(caveats), details=details)


def _log_box_mass(mean, cov, lo, hi, rng):
    """log of the mass of N(mean, cov) inside the box [lo, hi] and the coordinates whose bounds
    cut it (within 8 sd of the mean): a normal CDF for one, scipy's Genz integration for more."""
    sd = np.sqrt(np.diag(cov))
    cut = [i for i in range(len(mean)) if (mean[i] - lo[i]) / sd[i] < 8 or (hi[i] - mean[i]) / sd[i] < 8]
    if not cut:
        return 0.0, cut
    if len(cut) == 1:
        i = cut[0]
        a, b = (lo[i] - mean[i]) / sd[i], (hi[i] - mean[i]) / sd[i]
        if a > 0:  # the far tail: upper tail of a, less the tail beyond b (no cancellation)
            a, b = -b, -a
        return float(special.log_ndtr(b) + np.log1p(-np.exp(special.log_ndtr(a) - special.log_ndtr(b)))), cut
    with np.errstate(divide="ignore"):
        mass = stats.multivariate_normal.cdf(hi[cut], mean[cut], cov[np.ix_(cut, cut)], maxpts=200000 * len(cut),
                                             abseps=1e-12, releps=1e-6, lower_limit=lo[cut],
                                             rng=rng if rng is not None else np.random.default_rng(0))
    return (float(np.log(mass)) if mass > 0 else -np.inf), cut


def _bracket(log_target, draws, ess, rng, mean, cov, lo, hi, log_mass, n_check):
    """Evidence lower and upper bounds with ``q`` = N(mean, cov) truncated to the box and to the
    support: ELBO = E_q[log target - log q] over ``n_check`` draws of ``q``, EUBO = E_post[...]
    over at most ``n_check`` posterior draws (thinned evenly); each with its Monte Carlo error
    (the posterior draws' through their effective sample size).  Also the log of the mass of the
    box-truncated Gaussian where the target is finite (estimated from the same draws of q)."""
    d = len(mean)
    chol = np.linalg.cholesky(cov)
    log_gauss = mvn_logpdf(mean, chol)
    accept = math.exp(log_mass)
    kept, tried = [], 0
    while sum(len(k) for k in kept) < n_check and tried < 2_000_000:
        batch = int(min(2_000_000 - tried, max(1000, 1.2 * n_check / accept)))
        z = mean + rng.standard_normal((batch, d)) @ chol.T
        kept.append(z[np.all((z >= lo) & (z <= hi), axis=1)])
        tried += batch
    zq = np.concatenate(kept)[:n_check]
    if len(zq) < 50:
        raise LaplaceError(f"Laplace: too little of the Gaussian lies inside the prior bounds to check it "
                           f"({len(zq)} of {tried} draws)")
    lq = np.asarray(log_target(zq), dtype=float)
    finite = np.isfinite(lq)
    if finite.sum() < 50:
        raise LaplaceError("Laplace: the log target is -inf at almost all draws of its Gaussian (the model's "
                           "support is much narrower than the Gaussian)")
    frac = finite.mean()
    log_support = math.log(frac)
    support_se = math.sqrt((1 - frac) / (frac * len(zq)))
    log_norm = log_mass + log_support  # log q = log N - log_norm
    rq = lq[finite] - log_gauss(zq[finite]) + log_norm
    step = max(1, len(draws) // n_check)
    zp = draws[::step]
    lp = np.asarray(log_target(zp), dtype=float)
    if not np.all(np.isfinite(lp)):
        raise LaplaceError("Laplace: the log target is not finite at some posterior draws")
    rp = lp - log_gauss(zp) + log_norm
    n_eff = len(zp) if ess is None else max(2.0, min(len(zp), ess * len(zp) / len(draws)))
    return ({"elbo": float(rq.mean()), "elbo_se": float(rq.std(ddof=1) / math.sqrt(len(rq))),
             "eubo": float(rp.mean()), "eubo_se": float(rp.std(ddof=1) / math.sqrt(n_eff)),
             "log_mass_in_support": log_support, "log_mass_in_support_se": support_se,
             "n_gaussian_draws": len(zq), "n_posterior_draws": len(zp)}, len(zq) + len(zp))


def _derivatives(log_target, x0, f0, h, names):
    """Minus the Hessian and the gradient by central differences (2d^2 points, one call)."""
    d = len(x0)
    e = np.diag(h)
    points = [x0 + e[i] for i in range(d)] + [x0 - e[i] for i in range(d)]
    pairs = [(i, j) for i in range(d) for j in range(i + 1, d)]
    for i, j in pairs:
        points += [x0 + e[i] + e[j], x0 + e[i] - e[j], x0 - e[i] + e[j], x0 - e[i] - e[j]]
    points = np.array(points)
    f = np.asarray(log_target(points), dtype=float)
    if not np.all(np.isfinite(f)):
        bad = points[np.argmax(~np.isfinite(f))] - x0
        along = ", ".join(names[i] for i in np.flatnonzero(bad))
        raise LaplaceError(f"Laplace: the log target is -inf one finite-difference step from the mode along "
                           f"{along} inside the box of prior bounds (a bound that depends on other parameters, or the "
                           f"edge of the model's support)")
    fp, fm = f[:d], f[d:2 * d]
    H = np.empty((d, d))
    H[np.diag_indices(d)] = -(fp - 2 * f0 + fm) / h**2
    for k, (i, j) in enumerate(pairs):
        a, b, c, g = f[2 * d + 4 * k: 2 * d + 4 * k + 4]
        H[i, j] = H[j, i] = -(a - b - c + g) / (4 * h[i] * h[j])
    return H, (fp - fm) / (2 * h), len(points)
