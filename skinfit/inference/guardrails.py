"""Sampling guard rails: the warnings a finished run carries in its saved attributes.

Four checks, each a plain message in the fit's ``warnings`` attribute (shown by
``Fit.summary().attrs``, ``Fit.report_text()`` and the HTML report; ``skinfit fit --strict``
exits with status 3 when there is any):

* **not converged** within the step budget (the sampler's own reasons);
* **stuck walkers**, two ways: a walker that accepted fewer than ``STUCK_ACCEPTANCE`` (5%) of
  its proposals (healthy DE/snooker runs here accept 15-40%; below 5% it sits in a corner: a
  separate mode, a bound, a support edge), and a walker whose median log density lies more than
  ``STUCK_LOGP`` (5) typical spreads below the ensemble's median, a spread being the median over
  walkers of (median - 5% quantile) of their own log densities (for a d-dimensional Gaussian
  posterior the log density is -chi2_d / 2, so the rule scales with sqrt(d));
* **the data ask for values beyond a prior bound**: where the posterior piles on a finite prior
  bound (more than ``BOUND_SHARE`` (5%) of the draws within ``BOUND_WINDOW`` (0.25) posterior
  standard deviations of it, in the sampling coordinate: log for positive parameters, so a
  lower bound at 0 is never "hit"; and more than twice the prior's own share there), a
  likelihood-ratio test of the bound: LR = 2 (max log-likelihood with that one bound moved
  ``BOUND_REACH`` (10) posterior sds out, at most to the physical range the model card allows,
  - max log-likelihood within the prior bounds), both maxima by Powell's method from the best
  posterior draw, within 10 posterior sds of the draws, p = P(chi2_1 > LR) / 2 (Self & Liang
  1987, "Asymptotic properties of maximum likelihood estimators and likelihood ratio tests under
  nonstandard conditions": a parameter on the boundary of its range).  A warning when
  p < ``BOUND_ALPHA`` (0.01): the bound, not the data, limits the parameter.

A pile-up whose test finds no such evidence is not a failure but information, a **note**
(:func:`assess_run`'s second list; ``Fit.notes``, shown by ``report_text`` and the report,
never acted on by ``--strict``): a posterior reaches a bound where the priors put it, or where
the data place a parameter near its bound (e.g. tau0 of electroadhesion: the data determine
only tau0*beta0 and tau0*phi, and the priors of beta0 and phi tilt tau0 towards its upper bound
along that ridge).  The rates of every warning on fits of a correct model are measured in
bench/results/misfit.md.
"""

import math

import numpy as np

__all__ = ["STUCK_ACCEPTANCE", "STUCK_LOGP", "BOUND_WINDOW", "BOUND_SHARE", "BOUND_ALPHA", "BOUND_REACH",
           "PRIOR_DOMINATED", "assess_run", "check_run", "bound_share", "bound_test"]

STUCK_ACCEPTANCE = 0.05
STUCK_LOGP = 5.0
BOUND_WINDOW = 0.25
BOUND_SHARE = 0.05
BOUND_ALPHA = 0.01
#: how far past a bound its likelihood-ratio test looks, in posterior sds
BOUND_REACH = 10.0
#: contraction (1 - posterior / prior variance, sampling coordinate) below which the data
#: barely determine a parameter: the summary's "mostly prior" note
PRIOR_DOMINATED = 0.5
#: a log-likelihood the optimiser may step into that is -inf (outside the physical support)
_PENALTY = 1e12


def bound_share(z, z_prior, zb):
    """Shares of posterior draws ``z`` and prior draws ``z_prior`` (sampling coordinate) within
    ``BOUND_WINDOW`` posterior sds of the bound ``zb``."""
    width = BOUND_WINDOW * float(np.std(z))
    return float(np.mean(np.abs(z - zb) <= width)), float(np.mean(np.abs(z_prior - zb) <= width))


def _physical(post, slot):
    """The range the model card allows a slot's parameter (noise scales: [0, inf]); a positive
    parameter sampled on a log scale stays > 0."""
    ranges = {q.name: q.physical for q in post.model.parameters}
    lo, hi = ranges.get(slot.base, (0.0, math.inf) if slot.base in post.noise_names else (-math.inf, math.inf))
    return (max(lo, 0.0) if slot.log_scale else lo), hi


def bound_test(post, theta, j, side, log_lik=None):
    """Likelihood-ratio test of the prior bound ``side`` (lower | upper) of slot ``j``.

    Parameters
    ----------
    post : Posterior
    theta : (S, d) array
        Posterior draws (natural parameters): the best by log-likelihood starts the searches,
        which stay within ``BOUND_REACH`` posterior sds of the draws' range in every sampling
        coordinate (log for positive parameters): the question is whether the likelihood
        rises past the bound, not where a far maximum lies.
    j : int
    side : str
    log_lik : (S,) array, optional
        The draws' log-likelihood (computed when not given).

    Returns
    -------
    dict
        ``lr`` (2 x the gain in maximum log-likelihood when the bound moves out by
        ``BOUND_REACH`` posterior sds, at most to the physical range), ``p`` (P(chi2_1 > lr) / 2;
        1 when lr = 0), ``beyond`` (the parameter at the relaxed maximum) and ``evaluations``.
    """
    # imported here, not at the top: a saved fit's figures load this module, and scipy.stats
    # costs them ~0.5 s (tests/test_startup.py)
    from scipy import optimize, stats

    log = np.array([s.log_scale for s in post.slots])
    tiny = np.finfo(float).tiny  # a shifted-log slot may sit at exactly 0

    def coordinate(x):
        with np.errstate(divide="ignore"):
            return np.where(log, np.log(np.maximum(x, tiny)), x)

    def natural(u):
        return np.where(log, np.exp(u), u)

    def objective(u):
        with np.errstate(all="ignore"):
            value = post.log_likelihood(natural(u)[None])[0]
        return -value if np.isfinite(value) else _PENALTY

    theta = np.asarray(theta, dtype=float)
    if log_lik is None:
        with np.errstate(all="ignore"):
            log_lik = post.log_likelihood(theta)
    u = coordinate(theta)
    reach = BOUND_REACH * u.std(axis=0)
    lo = np.maximum(coordinate(np.array([s.lo for s in post.slots], dtype=float)), u.min(axis=0) - reach)
    hi = np.minimum(coordinate(np.array([s.hi for s in post.slots], dtype=float)), u.max(axis=0) + reach)
    start = np.clip(u[int(np.argmax(np.where(np.isfinite(log_lik), log_lik, -np.inf)))], lo, hi)
    inside = optimize.minimize(objective, start, method="Powell", bounds=optimize.Bounds(lo, hi))
    physical = np.array(_physical(post, post.slots[j]), dtype=float)
    if log[j]:
        with np.errstate(divide="ignore"):
            physical = np.log(physical)
    if side == "upper":
        hi[j] = max(hi[j], min(physical[1], hi[j] + reach[j]))
    else:
        lo[j] = min(lo[j], max(physical[0], lo[j] - reach[j]))
    beyond = optimize.minimize(objective, inside.x, method="Powell", bounds=optimize.Bounds(lo, hi))
    best = beyond if beyond.fun < inside.fun else inside
    lr = 2.0 * (inside.fun - best.fun) if inside.fun < _PENALTY else 0.0
    return {"lr": float(lr), "p": float(0.5 * stats.chi2.sf(lr, 1)) if lr > 0 else 1.0,
            "beyond": float(natural(best.x)[j]), "evaluations": int(inside.nfev + beyond.nfev)}


def _pile_up(post, theta, log_lik, j, side, b, share, share_prior, contraction):
    """The warning or note of a posterior piled on bound ``b`` of slot ``j``: the bound test,
    and (for the note's wording) whether the priors or the likelihood put the draws there: the
    mean log prior and mean log-likelihood of the draws within the window, each less its mean
    over all draws (``log_lik`` (S,) of the draws ``theta`` (S, d))."""
    s = post.slots[j]
    test = bound_test(post, theta, j, side, log_lik)
    pile = (f"{share:.0%} of the posterior draws lie within {BOUND_WINDOW} sd of the prior's {side} bound "
            f"{b:g} (prior: {share_prior:.0%})")
    lifted = (f"moving the bound {BOUND_REACH:g} posterior sd out raises the maximum log-likelihood by "
              f"{test['lr'] / 2:.2g} nats (likelihood-ratio p = {test['p']:.2g}; the maximum then at {s.name} = "
              f"{test['beyond']:.4g})")
    if test["p"] < BOUND_ALPHA:
        return "WARN", (f"{s.name}: the data ask for values beyond the prior's {side} bound {b:g}: {lifted}; {pile}; "
                        f"the bound, not the data, limits it")
    f = np.log if s.log_scale else np.asarray
    x = f(theta[:, j])
    near = np.abs(x - float(f(b))) <= BOUND_WINDOW * float(np.std(x))
    log_prior = post.log_prior(theta)
    by_prior = log_prior[near].mean() - log_prior.mean() >= log_lik[near].mean() - log_lik.mean()
    if by_prior or contraction < PRIOR_DOMINATED:
        return "NOTE", (f"the data do not determine {s.name} (prior-dominated): {pile}, put there by the priors "
                        f"(contraction {contraction:.2f}); the data do not ask for values beyond it: {lifted}. "
                        f"Information, not a failure")
    return "NOTE", (f"{s.name}: the data place it near the prior's {side} bound {b:g}: {pile}; they do not ask for "
                    f"values beyond it: {lifted}. Information, not a failure")


def assess_run(post, run):
    """Guard-rail problems and notes of one run.

    Parameters
    ----------
    post : Posterior
    run : SamplerRun
        Its kept chain (sampling coordinates), log densities and per-walker acceptance.

    Returns
    -------
    (list of dict, list of dict)
        The warnings: ``check`` (convergence | acceptance | stuck_walkers | bound), ``status``
        (FAIL | WARN), ``parameter`` (slot name or None) and ``message``, empty for a clean
        run; and the notes (``check`` bound, ``status`` NOTE): information, not failures.
    """
    out = []
    if not run.converged:
        out.append({"check": "convergence", "status": "FAIL", "parameter": None,
                    "message": f"not converged within the budget ({run.n_steps} steps): " + "; ".join(run.reasons)})
    stuck = np.flatnonzero(run.acceptance < STUCK_ACCEPTANCE)
    if len(stuck):
        out.append({"check": "acceptance", "status": "WARN", "parameter": None,
                    "message": f"{len(stuck)} of {len(run.acceptance)} walkers accept fewer than "
                               f"{STUCK_ACCEPTANCE:.0%} of their proposals (lowest {run.acceptance.min():.3f}, "
                               f"e.g. walker {stuck[0]}): stuck in a corner of the posterior"})
    lp = np.asarray(run.log_prob, dtype=float)
    if lp.ndim == 2 and lp.shape[1] >= 10 and np.isfinite(lp).all():
        med = np.median(lp, axis=1)
        spread = float(np.median(med - np.quantile(lp, 0.05, axis=1)))
        low = np.flatnonzero(med < np.median(med) - STUCK_LOGP * max(spread, 0.5))
        if len(low):
            out.append({"check": "stuck_walkers", "status": "WARN", "parameter": None,
                        "message": f"{len(low)} of {len(med)} walkers (e.g. walker {low[0]}) stay "
                                   f"{np.median(med) - med[low].max():.1f}+ nats below the ensemble's median "
                                   f"log density (typical spread {spread:.2f}): a separate mode or a stuck walker"})
    z = run.chain.reshape(-1, run.chain.shape[-1])
    theta = post.to_theta(z)
    notes, log_lik = [], None
    grid = (np.arange(4000) + 0.5) / 4000
    for j, s in enumerate(post.slots):
        log = s.log_scale
        f = np.log if log else np.asarray
        z_prior = f(s.prior.ppf(grid))
        for side, b in (("lower", s.lo), ("upper", s.hi)):
            if not math.isfinite(b) or (log and b <= 0):
                continue
            share, share_prior = bound_share(f(theta[:, j]), z_prior, float(f(b)))
            if share > BOUND_SHARE and share > 2 * share_prior:
                contraction = 1.0 - float(np.var(f(theta[:, j]))) / float(np.var(z_prior))
                if log_lik is None:  # the draws' log-likelihood from their log densities: no model call
                    with np.errstate(invalid="ignore"):
                        log_lik = np.asarray(run.log_prob, dtype=float).reshape(-1) - post.log_jacobian(z) \
                            - post.log_prior(theta)
                    log_lik = np.where(np.isfinite(log_lik), log_lik, -np.inf)
                status, message = _pile_up(post, theta, log_lik, j, side, b, share, share_prior, contraction)
                (out if status == "WARN" else notes).append(
                    {"check": "bound", "status": status, "parameter": s.name, "message": message})
    return out, notes


def check_run(post, run):
    """The warnings of :func:`assess_run` (its notes left out)."""
    return assess_run(post, run)[0]
