"""Sampling guard rails: the warnings a finished run carries in its saved attributes.

Three checks, each a plain message in the fit's ``warnings`` attribute (shown by
``Fit.summary().attrs``, ``Fit.report_text()`` and the HTML report; ``skinfit fit --strict``
exits with status 3 when there is any):

* **not converged** within the step budget (the sampler's own reasons);
* **stuck walkers**, two ways: a walker that accepted fewer than ``STUCK_ACCEPTANCE`` (5%) of
  its proposals (healthy DE/snooker runs here accept 15-40%; below 5% it sits in a corner: a
  separate mode, a bound, a support edge), and a walker whose median log density lies more than
  ``STUCK_LOGP`` (5) typical spreads below the ensemble's median, a spread being the median over
  walkers of (median - 5% quantile) of their own log densities (for a d-dimensional Gaussian
  posterior the log density is -chi2_d / 2, so the rule scales with sqrt(d));
* **mass piling on a bound**: more than ``BOUND_SHARE`` (5%) of the posterior draws lie within
  ``BOUND_WINDOW`` (0.25) posterior standard deviations of a finite prior bound, measured in the
  sampling coordinate (log for positive parameters, so a lower bound at 0 is never "hit"), and
  that share is more than twice the prior's own share there (a prior that itself puts mass at
  the bound is the user's statement, not a symptom).  The window scales with the posterior's
  width rather than the bound range: "1% of the range" would flag every posterior narrower than
  that range near a bound, and miss a wide one truncated by it.  The same criterion as the
  report's ``posterior mass on a prior bound`` row.
"""

import math

import numpy as np

__all__ = ["STUCK_ACCEPTANCE", "STUCK_LOGP", "BOUND_WINDOW", "BOUND_SHARE", "check_run", "bound_share"]

STUCK_ACCEPTANCE = 0.05
STUCK_LOGP = 5.0
BOUND_WINDOW = 0.25
BOUND_SHARE = 0.05


def bound_share(z, z_prior, zb):
    """Shares of posterior draws ``z`` and prior draws ``z_prior`` (sampling coordinate) within
    ``BOUND_WINDOW`` posterior sds of the bound ``zb``."""
    width = BOUND_WINDOW * float(np.std(z))
    return float(np.mean(np.abs(z - zb) <= width)), float(np.mean(np.abs(z_prior - zb) <= width))


def check_run(post, run):
    """Guard-rail problems of one run.

    Parameters
    ----------
    post : Posterior
    run : SamplerRun
        Its kept chain (sampling coordinates) and per-walker acceptance.

    Returns
    -------
    list of dict
        ``check`` (convergence | acceptance | stuck_walkers | bound), ``status`` (FAIL | WARN),
        ``parameter`` (slot name or None) and ``message``; empty for a clean run.
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
    theta = post.to_theta(run.chain.reshape(-1, run.chain.shape[-1]))
    grid = (np.arange(4000) + 0.5) / 4000
    for j, s in enumerate(post.slots):
        log = s.log_scale
        f = np.log if log else np.asarray
        for side, b in (("lower", s.lo), ("upper", s.hi)):
            if not math.isfinite(b) or (log and b <= 0):
                continue
            share, share_prior = bound_share(f(theta[:, j]), f(s.prior.ppf(grid)), float(f(b)))
            if share > BOUND_SHARE and share > 2 * share_prior:
                out.append({"check": "bound", "status": "WARN", "parameter": s.name,
                            "message": f"{s.name}: {share:.0%} of the posterior draws lie within {BOUND_WINDOW} sd "
                                       f"of the prior's {side} bound {b:g} (prior: {share_prior:.0%}); the bound, "
                                       f"not the data, limits it"})
    return out
