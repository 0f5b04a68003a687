"""The design problem: draws of the current distribution, a mean function and the noise, and
the likelihood pieces every estimator shares."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import special, stats

from skinfit.errors import InputError

__all__ = ["LOG_2PI", "CELLS", "DesignProblem", "gaussian_problem", "log_lik", "log_sum_lik", "noise_draws", "t_weight",
           "take_x", "n_candidates", "conditional_gain", "restrict_to_support"]


LOG_2PI = math.log(2.0 * math.pi)


#: (outer x inner x candidate) cells per vectorised block of the nested estimators
CELLS = 4_000_000


@dataclass(frozen=True)
class DesignProblem:
    """What the estimators need, in a coordinate ``u`` of the parameters (d of them).

    ``mean(u, X)``: u (k, d), X a mapping covariate -> (C,) SI array; returns (k, C, r), the
    expected observation of each of r observables in the space where the noise is additive
    (log of the observable for a log-normal likelihood; NaN outside the physical support).
    ``sigma`` (r,) the noise sd there; ``nu`` (r,) Student-t degrees of freedom (inf = normal).
    ``draws`` (D, d) of the current distribution (prior or posterior) in u; ``loc``, ``cov`` its
    Gaussian approximation; ``log_density(u)`` (k,) its log density for importance sampling and
    ``log_marginal(u, idx)`` (k,) that of the coordinates ``idx`` alone.
    """

    names: tuple
    mean: object
    sigma: np.ndarray
    nu: np.ndarray
    draws: np.ndarray
    loc: np.ndarray
    cov: np.ndarray
    log_density: object
    log_marginal: object
    observables: tuple = ("y",)
    noise_priors: tuple | None = None  # per observable, the prior of its noise sd (discrimination)
    # Before :func:`restrict_to_support` conditioned the draws on the physical support (all None
    # until it did): ``base_draws`` (D0, d) the unrestricted draws, ``in_support`` (D0,) bool the
    # ones kept as ``draws``, ``support`` the design points (covariate -> (P,) SI) at which every
    # kept draw predicts inside the support.  ``base_cov`` (d, d): the covariance whose
    # regression of nuisance on target coordinates turns a draw into one of the conditional
    # (a diagonal one for independent priors: swap, exactly); None = ``cov``.
    base_draws: np.ndarray | None = None
    in_support: np.ndarray | None = None
    support: dict | None = None
    base_cov: np.ndarray | None = None
    # A fit's posterior, whose nuisance coordinates given the targets are not Gaussian: its
    # unnormalised log density ``log_joint(v)`` (k,) in v = (u, extra) (k, d + e), the extra
    # coordinates (the fit's noise parameters, log) of each base draw in ``extra_draws`` (D0, e).
    # :func:`eig_nmc` then weights its conditional draws by it (self-normalised importance
    # sampling); None: the regression of ``base_cov`` alone (exact for a Gaussian, a prior file).
    log_joint: object = None
    extra_draws: np.ndarray | None = None

    @property
    def d(self):
        return len(self.names)

    def focus_index(self, params):
        """Indices of the target parameters ``params`` (None = all)."""
        if params is None:
            return np.arange(self.d)
        return np.array([self.names.index(p) for p in params])


def gaussian_problem(names, mean, sigma, loc, cov, draws, *, nu=None, observables=("y",)):
    """A :class:`DesignProblem` whose current distribution is the Gaussian N(loc, cov)."""
    loc, cov = np.asarray(loc, float), np.atleast_2d(np.asarray(cov, float))
    dist = stats.multivariate_normal(loc, cov)

    def log_marginal(u, idx):
        return np.atleast_1d(stats.multivariate_normal(loc[idx], cov[np.ix_(idx, idx)]).logpdf(u[..., idx]))

    sigma = np.atleast_1d(np.asarray(sigma, float))
    return DesignProblem(tuple(names), mean, sigma,
                         np.full(len(sigma), np.inf) if nu is None else np.asarray(nu, float),
                         np.asarray(draws, float), loc, cov, lambda u: np.atleast_1d(dist.logpdf(u)), log_marginal,
                         tuple(observables))


def log_lik(y, mu, sigma, nu):
    """log p(y | mu) summed over the last axis (observables): normal or Student-t, broadcasting;
    -inf where mu is NaN (outside the support)."""
    z = (y - mu) / sigma
    if np.all(np.isinf(nu)):
        ll = -0.5 * z * z - np.log(sigma) - 0.5 * LOG_2PI
    else:
        ll = (np.where(np.isinf(nu), stats.norm.logpdf(z), stats.t.logpdf(z, np.where(np.isinf(nu), 1.0, nu)))
              - np.log(sigma))
    return np.where(np.isnan(ll), -np.inf, ll).sum(axis=-1)


def log_sum_lik(y, mu, sigma, nu, offset=None):
    """log sum_m exp(offset[n, m]) p(y_n | mu_m) for y (N, C, r), mu (M, C, r), offset (N, M)
    or None -> (N, C): the hot loop of the nested estimators, in place for a normal likelihood
    (NaN predictions count as zero likelihood)."""
    if not np.all(np.isinf(nu)):
        ll = log_lik(y[:, None], mu[None], sigma, nu)
        return special.logsumexp(ll if offset is None else ll + offset[:, :, None], axis=1)
    mu = np.where(np.isnan(mu), np.inf, mu) / sigma
    y = y / sigma
    q = np.zeros((len(y), len(mu), y.shape[1]))
    for r in range(y.shape[2]):
        d = np.subtract(y[:, None, :, r], mu[None, :, :, r])
        d *= d
        q += d
    q *= -0.5
    if offset is not None:
        q += offset[:, :, None]
    top = q.max(axis=1)
    top = np.where(np.isfinite(top), top, 0.0)
    q -= top[:, None]
    np.exp(q, out=q)
    with np.errstate(divide="ignore"):
        return np.log(q.sum(axis=1)) + top - np.log(sigma).sum() - 0.5 * LOG_2PI * y.shape[2]


def noise_draws(rng, shape, nu):
    """Standardised noise draws of shape (..., r)."""
    eps = rng.standard_normal(shape)
    if not np.all(np.isinf(nu)):
        df = np.broadcast_to(np.where(np.isinf(nu), 1.0, nu), shape)
        eps = np.where(np.isinf(nu), eps, rng.standard_t(df))
    return eps


def t_weight(nu):
    """sqrt of the Fisher information of a Student-t location relative to a normal's,
    (nu + 1) / (nu + 3); 1 for a normal likelihood (nu = inf)."""
    finite = np.where(np.isinf(nu), 1.0, nu)
    return np.where(np.isinf(nu), 1.0, np.sqrt((finite + 1) / (finite + 3)))


def take_x(X, idx):
    return {k: np.asarray(v)[idx] for k, v in X.items()}


def n_candidates(X):
    return len(next(iter(X.values())))


def conditional_gain(cov, focus):
    """B (d - f, f) = Sigma_eta,psi Sigma_psi,psi^-1 for the target coordinates ``focus`` (psi)
    and the rest (eta) of a covariance ``cov`` (d, d): for a Gaussian, eta + B (psi* - psi) of
    a joint draw (psi, eta) is a draw of eta | psi*, exactly; B = 0 (a plain swap) when the
    cross-covariance is zero, as for the independent priors of a prior file."""
    nuis = np.setdiff1d(np.arange(len(cov)), focus)
    try:
        return np.linalg.solve(cov[np.ix_(focus, focus)], cov[np.ix_(focus, nuis)]).T
    except np.linalg.LinAlgError:  # a target without spread in the draws: least squares
        return np.linalg.lstsq(cov[np.ix_(focus, focus)], cov[np.ix_(focus, nuis)], rcond=None)[0].T


def restrict_to_support(problem, designs, chunk=None):
    """Condition the current distribution on predictions inside the physical support at every
    point of ``designs``: draws outside are dropped, the Gaussian approximation (loc, cov) is
    refitted to the rest, and the densities for importance sampling become the restricted ones,
    p(u) 1[valid] / Z, Z the kept fraction of the draws.  The marginal of a target subset psi
    picks up P(valid | psi) / Z, P(valid | psi) over 200 draws of the nuisance coordinates given
    psi (:func:`conditional_gain`).  The unrestricted draws and covariance are kept for the
    conditional draws of :func:`eig_nmc`.  Returns (problem, number dropped)."""
    X_all = {k: np.concatenate([np.asarray(X[k], float) for X in designs]) for k in designs[0]}
    chunk = chunk or max(1, CELLS // max(n_candidates(X_all), 1))

    def valid(u):
        u = np.atleast_2d(u)
        return np.concatenate([np.isfinite(problem.mean(u[i:i + chunk], X_all)).all(axis=(1, 2))
                               for i in range(0, len(u), chunk)]) if len(u) else np.zeros(0, bool)

    ok = valid(problem.draws)
    if ok.sum() < 50:
        raise InputError("candidates", f"only {int(ok.sum())} of {len(ok)} parameter draws give predictions inside "
                         f"the model's physical support at every candidate: narrow the candidate range")
    base_cov = np.atleast_2d(problem.cov if problem.base_cov is None else problem.base_cov)
    keep = dict(base_draws=problem.draws, in_support=ok, support=X_all, base_cov=base_cov)
    if ok.all():
        return replace(problem, **keep), 0
    draws = problem.draws[ok]
    loc, cov = draws.mean(axis=0), np.atleast_2d(np.cov(draws, rowvar=False))
    log_z = math.log(ok.mean())
    base, base_marginal = problem.log_density, problem.log_marginal
    sample = problem.draws[:200]

    def log_density(u):
        u = np.atleast_2d(u)
        return np.where(valid(u), base(u) - log_z, -np.inf)

    def log_marginal(u, idx):
        u = np.atleast_2d(u)
        idx = np.atleast_1d(idx)
        nuis = np.setdiff1d(np.arange(problem.d), idx)
        gain = conditional_gain(base_cov, idx)
        out = base_marginal(u, idx) - log_z
        for i, row in enumerate(u):
            given = sample.copy()
            given[:, nuis] += (row[idx] - sample[:, idx]) @ gain.T
            given[:, idx] = row[idx]
            frac = valid(given).mean()
            out[i] += math.log(frac) if frac > 0 else -np.inf
        return out

    return replace(problem, draws=draws, loc=loc, cov=cov, log_density=log_density, log_marginal=log_marginal,
                   **keep), int((~ok).sum())
