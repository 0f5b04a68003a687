"""Metropolis-within-Gibbs for a population of subjects: the sampler behind
:func:`skinfit.analysis.population.population.population` (``method="gibbs"``).

Choices, by measurement (bench/results/population.md, CPU s on 13 contact_area subjects x 8
parameters): the likelihood of all subjects in one forward call (:class:`_Stacked`, checked
against the per-subject calls at the start) took the run from 23.4 to 12.6 s CPU with the
same chain (the per-subject calls were 60% of it); joint location-and-scale moves along the
non-centred coordinates (3. below) for the parameters whose subjects are weakly informed,
with convergence checks on the thinned draws at growing intervals, 12.6 -> 10.2 s.

State per chain: every subject's full sampled vector ``z_i`` (its Posterior's sampling
coordinates: population parameters, noise scales and any parameter left per subject) and the
hyper-parameters ``mu``, ``Sigma`` of the population parameters in their population coordinate
``u`` (``log theta`` for log-normal families, ``theta`` for normal and Student-t).  One sweep:

1. **Subjects** (one vectorised likelihood call per subject for all chains): independence
   Metropolis-Hastings from a multivariate t (5 d.o.f.) whose precision and location are the
   Gaussian approximation of the subject's separate fit (mean, covariance of its draws), with
   the prior of the population parameters divided out and the current population multiplied
   in (information form; both in ``u`` linearised in ``z`` at the separate fit's mean, where
   product, shift or shear coordinates mix slots or ``u`` and ``z`` differ).  The proposal
   depends on the hyper-parameters only, so it is a valid Gibbs-block proposal; the exact
   target (likelihood x population density x the prior of the other parameters x Jacobian)
   enters through the acceptance ratio.
2. **Hyper-parameters**, exact conditionals: ``mu | Sigma, u`` normal (prior
   ``Normal(c, 2 s)`` per parameter); ``Sigma`` with the prior of Huang & Wand (2013,
   "Simple marginally noninformative prior distributions for covariance matrices", Bayesian
   Analysis 8, 439), ``Sigma | a ~ InvWishart(nu + p - 1, 2 nu diag(1 / a))``,
   ``a_k ~ InvGamma(1/2, 1 / s_k^2)``, with ``nu = 2``: each population sd is half-t(2, s_k)
   and, when correlated, every correlation is uniform on (-1, 1).  Independent populations
   use the same half-t(2, s_k) through its inverse-gamma pair.  Student-t populations
   (``nu_t = 4``) add per-subject precision weights ``w ~ Gamma`` (scale-mixture form).
3. **Location and scale moves** (:func:`_shift_move`): ``mu_j -> mu_j + d``,
   ``sd_j -> sd_j e^eps`` with every subject's ``u_ij`` moved along ``mu_j + sd_j eta_ij``
   (the non-centred coordinates ``eta`` held fixed; for a correlated population
   ``Sigma -> D Sigma D``), a Metropolis step with its Jacobian that needs one more
   likelihood call for all subjects; one per weakly informed parameter and sweep.  It
   crosses the funnel between the hyper-parameters and the subjects when their data are
   weak (few presses, a slope with a condition), where the centred Gibbs updates alone move
   ``mu`` and ``sd`` slowly.  Checked against quadrature (tests/test_population.py).  Used
   where the other slots' natural values do not depend on the population slots (no product
   or shear coordinate ties them to one): the moves hold them fixed in ``z``.

The population density is not renormalised inside a parameter's prior bounds (which stay
hard): exact when the population puts negligible mass outside them.
"""

import math

import numpy as np

from skinfit.errors import InputError
from skinfit.posterior import standardised_squares
from skinfit.io.priors import LOG_DENSITIES

__all__ = ["Spec", "run_gibbs", "NU_HYPER", "NU_T"]

NU_HYPER = 2.0  # Huang-Wand nu: half-t(2) population sds, uniform correlations
NU_T = 4.0  # degrees of freedom of a Student-t population
NU_PROPOSAL = 5.0  # degrees of freedom of the subjects' independence proposals


class Spec:
    """What the sampler needs to know of the population parameters (p of them).

    ``index`` (p,) slot indices in each subject's Posterior; ``log`` (p,) population coordinate
    is log theta; ``student`` (p,) Student-t population; ``centre``, ``scale`` (p,) hyper-prior
    ``mu ~ Normal(centre, 2 scale)``, ``sd ~ half-t(2, scale)``; ``correlated``.
    """

    def __init__(self, index, log, student, centre, scale, correlated):
        self.index = np.asarray(index, dtype=int)
        self.log = np.asarray(log, dtype=bool)
        self.student = np.asarray(student, dtype=bool)
        self.centre = np.asarray(centre, dtype=float)
        self.scale = np.asarray(scale, dtype=float)
        self.correlated = bool(correlated)
        self.p = len(self.index)


class _Subjects:
    """All S subjects: their Posteriors (the same slots), the Gaussian summaries of their
    separate fits in sampling coordinates (stacked), and the prior pieces the population
    replaces.  Everything but the likelihood is evaluated for all (chain, subject) at once."""

    def __init__(self, posts, moments, spec):
        self.posts = posts
        self.S = len(posts)
        first = posts[0]
        self.d = d = first.ndim
        covs = np.stack([np.atleast_2d(c) for _, c in moments])
        covs = covs + 1e-9 * np.einsum("sii->si", covs)[:, :, None] * np.eye(d)[None]
        self.A = np.linalg.inv(covs)  # (S, d, d)
        self.b = np.einsum("sij,sj->si", self.A, np.stack([m for m, _ in moments]))
        self.lo = np.array([s.lo for s in first.slots])
        self.hi = np.array([s.hi for s in first.slots])
        pop = set(spec.index.tolist())
        self.rest = [j for j in range(d) if j not in pop]
        # one transform for all subjects when their sampling maps are the same (same constants)
        self.shared_map = all(p.constants == first.constants and p.names == first.names for p in posts)
        # the population coordinates u of the population slots as a linear function of z at each
        # separate fit's mean, u ~ r0 + J z (a Jacobian by central differences through the
        # sampling map: product, shift and shear coordinates mix slots), so that the population
        # and the prior it replaces enter the proposals in z; and the prior of the population
        # slots in u (moments of 2000 prior quantiles), divided out there
        zbar = np.stack([m for m, _ in moments])
        step = np.maximum(1e-4 * np.sqrt(np.einsum("sii->si", covs)), 1e-8 * np.maximum(1.0, np.abs(zbar)))
        dz = np.eye(d)[:, None, :] * step[None]  # (d, S, d)
        plus, _ = self.transform(zbar[None] + dz)
        minus, _ = self.transform(zbar[None] - dz)
        dtheta = np.moveaxis((plus - minus) / (2 * step.T[:, :, None]), 0, -1)  # (S, d, d): d theta_i / d z_k
        theta0, _ = self.transform(zbar)
        tp = theta0[:, spec.index]
        with np.errstate(divide="ignore", invalid="ignore"):
            u0 = np.where(spec.log, np.log(tp), tp)
            self.J = np.where(spec.log, 1.0 / tp, 1.0)[:, :, None] * dtheta[:, spec.index, :]  # (S, p, d)
        self.r0 = u0 - np.einsum("spd,sd->sp", self.J, zbar)
        #: the other slots' natural values do not depend on the population slots' z (no product or
        #: shear ties them to a population slot): the location and scale moves hold them fixed in z
        self.separable = not np.any(dtheta[:, self.rest][:, :, spec.index])
        u = (np.arange(2000) + 0.5) / 2000
        pm, pv = np.empty((self.S, spec.p)), np.empty((self.S, spec.p))
        for i, post in enumerate(posts):
            for k, (j, lg) in enumerate(zip(spec.index, spec.log)):
                q = post.slots[j].prior.ppf(u)
                q = np.log(q) if lg else q
                pm[i, k], pv[i, k] = q.mean(), q.var()
        self.prior_prec, self.prior_mean = 1.0 / pv, pm
        self.stacked = None
        # prior of the other slots: one call per slot where every subject has the same prior
        self.rest_priors = []
        for j in self.rest:
            pri = [post.slots[j].prior for post in posts]
            if all(q.dist == pri[0].dist and dict(q.args) == dict(pri[0].args) for q in pri):
                self.rest_priors.append((j, None, LOG_DENSITIES[pri[0].dist], pri[0].args))
            else:
                self.rest_priors += [(j, i, LOG_DENSITIES[q.dist], q.args) for i, q in enumerate(pri)]

    def transform(self, z):
        """Natural parameters and log-Jacobian of z (..., S, d) -> ((..., S, d), (..., S))."""
        shape = z.shape
        if self.shared_map:
            theta, lj = self.posts[0]._transform(z.reshape(-1, self.d))
            return theta.reshape(shape), lj.reshape(shape[:-1])
        zs = z.reshape(-1, self.S, self.d)
        out = [self.posts[i]._transform(zs[:, i]) for i in range(self.S)]
        theta = np.stack([o[0] for o in out], axis=1).reshape(shape)
        return theta, np.stack([o[1] for o in out], axis=1).reshape(shape[:-1])

    def to_z(self, theta):
        shape = theta.shape
        if self.shared_map:
            return self.posts[0].to_z(theta.reshape(-1, self.d)).reshape(shape)
        ts = theta.reshape(-1, self.S, self.d)
        return np.stack([self.posts[i].to_z(ts[:, i]) for i in range(self.S)], axis=1).reshape(shape)

    def inside(self, theta):
        return np.all((theta >= self.lo) & (theta <= self.hi), axis=-1)

    def log_likelihood(self, theta):
        """theta (C, S, d) -> (C, S); -inf outside the prior bounds.  One forward call for all
        subjects (:class:`_Stacked`) where that reproduces the subjects' own likelihoods, else
        one call per subject."""
        inside = self.inside(theta)
        if self.stacked is not None:
            with np.errstate(all="ignore"):
                ll = np.where(inside, self.stacked(theta), -np.inf)
        else:
            ll = self._loop_likelihood(theta, inside)
        if np.isnan(ll).any():
            c, i = np.argwhere(np.isnan(ll))[0]
            post = self.posts[i]
            raise FloatingPointError(f"{post.model.id}: NaN log-likelihood at {dict(zip(post.names, theta[c, i]))}")
        return ll

    def _loop_likelihood(self, theta, inside):
        ll = np.full(theta.shape[:2], -np.inf)
        for i, post in enumerate(self.posts):
            ok = inside[:, i]
            if ok.any():
                with np.errstate(all="ignore"):
                    ll[ok, i] = post.log_likelihood(theta[ok, i])
        return ll

    def use_stacked(self, theta):
        """Switch to the one-call likelihood if it gives the subjects' own log-likelihoods at
        ``theta`` (C, S, d) (the starting states) to 1e-9 relative; returns whether it does."""
        try:
            st = _Stacked(self.posts)
        except _NotStackable:
            return False
        inside = self.inside(theta)
        with np.errstate(all="ignore"):
            a = np.where(inside, st(theta), -np.inf)
        b = self._loop_likelihood(theta, inside)
        fin = np.isfinite(b)
        if np.array_equal(fin, np.isfinite(a)) and np.allclose(a[fin], b[fin], rtol=1e-9, atol=1e-9):
            self.stacked = st
        return self.stacked is not None

    def log_prior_part(self, theta, log_jac, mu, prec, spec):
        """Everything in a subject's conditional but the likelihood (up to a constant):
        theta (..., C, S, d), log_jac (..., C, S); mu (C, p), prec (C, S, p, p) -> (..., C, S)."""
        with np.errstate(all="ignore"):
            tp = theta[..., spec.index]
            u = np.where(spec.log, np.log(tp), tp)
            r = u - mu[:, None, :]
            quad = np.einsum("...csi,csij,...csj->...cs", r, prec, r)
            lp = -0.5 * quad - np.where(spec.log, u, 0.0).sum(axis=-1) + log_jac  # du/dtheta = 1/theta
            for j, i, logpdf, args in self.rest_priors:
                if i is None:
                    lp += logpdf(theta[..., j], args, None, None)
                else:
                    lp[..., i] += logpdf(theta[..., i, j], args, None, None)
        return np.where(self.inside(theta) & np.isfinite(lp), lp, -np.inf)


class _NotStackable(Exception):
    pass


class _Stacked:
    """The log-likelihoods of all S subjects in one forward call: the subjects' distinct rows
    (:meth:`Posterior._unique_rows`) concatenated (N rows), each parameter given per row as
    (C, N), and the normal / log-normal sums of squares reduced per subject.  Needs one model,
    the same constants and normal or log-normal noise; :meth:`_Subjects.use_stacked` checks
    the result against the subjects' own likelihoods before it is used."""

    def __init__(self, posts):
        first = posts[0]
        try:
            same = all(p.model is first.model or p.model.id == first.model.id for p in posts) and all(
                p.constants.keys() == first.constants.keys()
                and all(np.array_equal(p.constants[k], first.constants[k]) for k in first.constants) for p in posts)
        except (TypeError, ValueError):
            same = False
        if not same or any(p.noise[o] not in ("normal", "lognormal") for p in posts for o in p.observables) or any(
                p.observables != first.observables or p._param_index_u.keys() != first._param_index_u.keys()
                for p in posts):
            raise _NotStackable
        self.model, self.constants, self.observables = first.model, first.constants, first.observables
        sizes = [p.n_unique for p in posts]
        self.starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(int)
        self.row_subject = np.repeat(np.arange(len(posts)), sizes)
        self.x = {c: np.concatenate([p._xu[c] for p in posts]) for c in first._xu}
        self.slot = {k: np.concatenate([np.broadcast_to(p._param_index_u[k], (p.n_unique,)) for p in posts])
                     for k in first._param_index_u}
        self.counts = np.concatenate([p._counts for p in posts])
        self.noise = {o: first.noise[o] for o in self.observables}
        self.sigma = {o: f"sigma{first._suffix(o)}" for o in self.observables}
        self.zbar = {o: np.concatenate([p._zbar[o] for p in posts]) for o in self.observables}
        self.ssw = {o: np.concatenate([p._ssw[o] for p in posts]) for o in self.observables}
        self.const = sum(np.array([0.5 * p.n * math.log(2 * math.pi) + p._sum_logy.get(o, 0.0) for p in posts])
                         for o in self.observables)

    def __call__(self, theta):
        """theta (C, S, d) -> (C, S); not masked for prior bounds (the caller does)."""
        C, N = len(theta), len(self.row_subject)
        params = {k: theta[:, self.row_subject, j] for k, j in self.slot.items()}
        pred, ok = self.model.forward(params, self.x, self.constants)
        total = np.zeros((C, N))
        for o in self.observables:
            sigma = params[self.sigma[o]]
            mean = np.broadcast_to(pred[o], (C, N))
            squares = standardised_squares(self.zbar[o], self.ssw[o], self.counts, mean, sigma,
                                           self.noise[o] == "lognormal")
            total += 0.5 * squares + self.counts * np.log(sigma)
        ll = -np.add.reduceat(total, self.starts, axis=1) - self.const
        ok = np.broadcast_to(np.asarray(ok), (C, N))
        return np.where(np.logical_and.reduceat(ok, self.starts, axis=1), ll, -np.inf)


def _proposal(subs, mu, prec, spec):
    """Location (C, S, d) and Cholesky factor (C, S, d, d) of the precision of the independence
    proposals: the separate fit's Gaussian, its own prior of the population slots divided out
    (where that leaves a positive-definite precision) and the population multiplied in, both
    in u linearised in z at the fit's mean (``u ~ r0 + J z``: :class:`_Subjects`)."""
    J, r0 = subs.J, subs.r0
    C, S, d = len(mu), subs.S, subs.d
    JtP = np.einsum("spi,cspq->csiq", J, prec)  # (C, S, d, p)
    Q = subs.A[None] + np.einsum("csiq,sqj->csij", JtP, J)
    h = subs.b[None] + np.einsum("csiq,csq->csi", JtP, mu[:, None, :] - r0[None])
    Qd = Q - np.einsum("spi,sp,spj->sij", J, subs.prior_prec, J)[None]
    hd = h - np.einsum("spi,sp->si", J, subs.prior_prec * (subs.prior_mean - r0))[None]
    try:
        L = np.linalg.cholesky(Qd)
        Q, h = Qd, hd
    except np.linalg.LinAlgError:
        ok = np.linalg.eigvalsh(Qd)[..., 0] > 1e-9 * np.linalg.eigvalsh(Q)[..., -1]
        Q = np.where(ok[..., None, None], Qd, Q)
        h = np.where(ok[..., None], hd, h)
        try:
            L = np.linalg.cholesky(Q)
        except np.linalg.LinAlgError:  # round-off (a population far narrower than the fit): clip
            lam, vec = np.linalg.eigh(Q)
            lam = np.maximum(lam, 1e-12 * lam[..., -1:])
            Q = np.einsum("...ij,...j,...kj->...ik", vec, lam, vec)
            L = np.linalg.cholesky(Q)
    loc = np.linalg.solve(Q, h[..., None])[..., 0]
    return loc, L


def _t_logpdf(x, loc, L, nu):
    """Multivariate t log-density with location ``loc`` and precision ``L L^T``: x (..., d)."""
    from scipy.special import gammaln  # here, not with the module: reading a cached population needs no scipy

    d = x.shape[-1]
    y = np.einsum("...ji,...j->...i", L, x - loc)  # L^T (x - loc)
    q = (y * y).sum(axis=-1)
    logdet = np.log(np.diagonal(L, axis1=-2, axis2=-1)).sum(axis=-1)
    return (gammaln(0.5 * (nu + d)) - gammaln(0.5 * nu) - 0.5 * d * math.log(nu * math.pi) + logdet
            - 0.5 * (nu + d) * np.log1p(q / nu))


def _t_draw(loc, L, nu, rng):
    e = rng.standard_normal(loc.shape)
    y = np.linalg.solve(np.swapaxes(L, -1, -2), e[..., None])[..., 0]  # L^-T e: covariance Q^-1
    return loc + y / np.sqrt(rng.chisquare(nu, loc.shape[:-1]) / nu)[..., None]


def _inv_gamma(shape, rate, rng):
    return rate / rng.gamma(shape)


def _inv_wishart(df, psi, rng):
    """Draws (k, p, p) of InvWishart(df, psi[k]) by Bartlett's decomposition of the Wishart."""
    k, p, _ = psi.shape
    Lw = np.linalg.cholesky(np.linalg.inv(psi))
    A = np.zeros((k, p, p))
    A[:, np.arange(p), np.arange(p)] = np.sqrt(rng.chisquare(df - np.arange(p), (k, p)))
    low = np.tril_indices(p, -1)
    A[:, low[0], low[1]] = rng.standard_normal((k, len(low[0])))
    LA = Lw @ A
    return np.linalg.inv(LA @ np.swapaxes(LA, 1, 2))


def run_gibbs(posts, moments, starts, spec, rng, *, chains=8, burn=300, ess_target=400, rhat_max=1.01,
              check_every=100, max_sweeps=20000, keep=1000, shift_move=True):
    """Sample the population posterior.

    Parameters
    ----------
    posts : list of S Posterior (the same slots)
    moments : list of S (mean (d,), cov (d, d)) of each separate fit in sampling coordinates
    starts : list of S arrays (n_i, d) of separate-fit draws in sampling coordinates (chain starts)
    spec : Spec
    rng : numpy Generator
    chains : parallel chains (vectorised); R-hat is computed over them
    burn, check_every, max_sweeps : sweeps discarded, sweeps between convergence checks, cap
    ess_target, rhat_max : stop when every hyper-parameter has bulk and tail ESS >= ess_target
        and R-hat <= rhat_max
    keep : draws kept per chain (the chains are thinned to at most this many; at most 2 keep are
        held while sampling, so memory does not grow with max_sweeps)
    shift_move : the location and scale moves (3. above) for weakly informed parameters

    Returns
    -------
    dict with ``mu``, ``sd`` (chains, draws, p), ``corr`` (chains, draws, p, p), ``theta``
    (chains, draws, S, d) natural parameters of every subject slot, and diagnostics.
    """
    import arviz as az

    if not 0 <= burn < max_sweeps or chains < 2 or keep < 1:
        raise InputError("run_gibbs", f"expected 0 <= burn < max_sweeps, chains >= 2 and keep >= 1 (got burn {burn}, "
                         f"max_sweeps {max_sweeps}, chains {chains}, keep {keep})")
    S, p, C = len(posts), spec.p, chains
    subs = _Subjects(posts, moments, spec)
    z = np.stack([st[rng.choice(len(st), C, replace=len(st) < C)] for st in starts], axis=1)  # (C, S, d)
    theta, lj = subs.transform(z)
    subs.use_stacked(theta)
    ll = subs.log_likelihood(theta)
    u = _u_of(theta, spec)
    mu = u.mean(axis=1)
    var = np.maximum(u.var(axis=1), (0.1 * spec.scale) ** 2)
    Sigma = np.zeros((C, p, p))
    Sigma[:, np.arange(p), np.arange(p)] = var
    a = np.broadcast_to(spec.scale**2, (C, p)).copy()
    w = np.ones((C, S, p))
    accept = np.zeros(S)
    # parameters whose subjects' data are weak against the population spread (a funnel between
    # the hyper-parameters and the subjects, where centred Gibbs moves them slowly) get the
    # non-centred moves: median within-subject variance of u against the between-subject
    # variance of the separate means (recomputed from the burn-in's sds half-way through it)
    u_sep = [_u_of(subs.posts[i].to_theta(st), spec) for i, st in enumerate(starts)]
    within = np.median([np.var(x, axis=0) for x in u_sep], axis=0)
    between = np.var([np.mean(x, axis=0) for x in u_sep], axis=0)
    weak = within > 0.25 * np.maximum(between - within, 1e-3 * between)
    shift = _ShiftMoves(shift_move and subs.separable, weak, np.sqrt(within / S), spec)
    # every stride-th sweep after the burn-in is kept; the stride doubles whenever 2 keep are held,
    # so exactly the draws thinned by ceil(n / keep) while n < 2 keep
    draws, stride = {"mu": [], "Sigma": [], "theta": []}, 1
    sweeps, checks, converged, next_check = 0, [], False, burn + check_every
    while sweeps < max_sweeps:
        # 1. every subject, all chains: independence Metropolis-Hastings
        prec = _pop_precision(Sigma, w, spec)  # (C, S, p, p)
        loc, L = _proposal(subs, mu, prec, spec)
        x = _t_draw(loc, L, NU_PROPOSAL, rng)
        both, lj2 = subs.transform(np.stack([x, z]))
        lp2 = subs.log_prior_part(both, lj2, mu, prec, spec)
        ll_x = np.full((C, S), -np.inf)
        fin = np.isfinite(lp2[0])
        if fin.any():
            ll_x = subs.log_likelihood(np.where(fin[..., None], both[0], np.nan))
        lq = _t_logpdf(np.stack([x, z]), loc, L, NU_PROPOSAL)
        log_r = (lp2[0] + ll_x) - (lp2[1] + ll) + lq[1] - lq[0]
        take = np.log(rng.random((C, S))) < np.where(np.isfinite(log_r), log_r, -np.inf)
        z = np.where(take[..., None], x, z)
        ll = np.where(take, ll_x, ll)
        theta = np.where(take[..., None], both[0], both[1])
        if sweeps >= burn:
            accept += take.mean(axis=0)
        u = _u_of(theta, spec)
        # 2. hyper-parameters from their exact conditionals
        mu, Sigma, a, w = _hyper_step(u, mu, Sigma, a, w, spec, rng)
        # 3. location and scale moves along the non-centred coordinates
        for k, (d, eps) in enumerate(shift.steps(C, rng)):
            took, z, ll, mu, Sigma, theta = _shift_move(subs, z, ll, theta, _u_of(theta, spec), mu, Sigma, a, spec,
                                                        d, eps, rng)
            shift.record(k, took, sweeps >= burn)
        if sweeps < burn:
            shift.adapt(sweeps, burn, mu, Sigma, within)
        sweeps += 1
        if sweeps > burn and (sweeps - burn - 1) % stride == 0:
            draws["mu"].append(mu.copy())
            draws["Sigma"].append(Sigma.copy())
            draws["theta"].append(theta.copy())
            if len(draws["mu"]) == 2 * keep:  # memory bounded whatever max_sweeps: every other draw
                draws = {k: v[::2] for k, v in draws.items()}
                stride *= 2
        if sweeps >= next_check:  # on the draws as they would be kept (thinned to <= keep a chain)
            n = sweeps - burn
            th = max(1, math.ceil(len(draws["mu"]) / keep))
            hyper = _hyper_draws(np.stack(draws["mu"][::th], 1), np.stack(draws["Sigma"][::th], 1), spec)
            ess_b = min(float(np.min(az.ess(v))) for v in hyper.values())
            ess_t = min(float(np.min(az.ess(v, method="tail", prob=(0.05, 0.95)))) for v in hyper.values())
            rhat = max(float(np.nanmax(az.rhat(v))) for v in hyper.values())
            checks.append({"sweeps": sweeps, "ess_bulk": ess_b, "ess_tail": ess_t, "rhat": rhat})
            if min(ess_b, ess_t) >= ess_target and rhat <= rhat_max:
                converged = True
                break
            next_check = sweeps + max(check_every, int(0.1 * n))
    n = sweeps - burn
    th = max(1, math.ceil(len(draws["mu"]) / keep))
    out = {k: np.stack(v[::th], axis=1) for k, v in draws.items()}  # (C, <= keep, ...)
    thin = stride * th
    out.update(_hyper_draws(out.pop("mu"), out.pop("Sigma"), spec))
    out.update(converged=converged, sweeps=sweeps, burn=burn, thin=thin, checks=checks,
               acceptance=(accept / max(n, 1)).tolist(),
               scale_acceptance=shift.acceptance())
    return out


def _u_of(theta, spec):
    tp = theta[..., spec.index]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(spec.log, np.log(tp), tp)


def _hyper_draws(mu, Sigma, spec):
    sd = np.sqrt(np.diagonal(Sigma, axis1=-2, axis2=-1))
    out = {"mu": mu, "sd": sd}
    if spec.correlated and spec.p > 1:
        out["corr"] = Sigma / (sd[..., :, None] * sd[..., None, :])
    return out


def _pop_precision(Sigma, w, spec):
    """Population precision for every chain and subject (C, S, p, p) (a subject's Student-t
    weights ``w`` (C, S, p) scale its variances)."""
    if spec.correlated:
        return np.broadcast_to(np.linalg.inv(Sigma)[:, None], (len(Sigma), w.shape[1], spec.p, spec.p))
    dprec = w / np.diagonal(Sigma, axis1=1, axis2=2)[:, None, :]
    return dprec[..., :, None] * np.eye(spec.p)


def _hyper_step(u, mu, Sigma, a, w, spec, rng):
    """One exact Gibbs update of (mu, Sigma, a, w) given the subjects' u (C, S, p)."""
    C, S, p = u.shape
    prior_prec = 1.0 / (2.0 * spec.scale) ** 2
    nu = NU_HYPER
    if spec.correlated:
        prec = np.linalg.inv(Sigma)
        Lam = np.diag(prior_prec)[None] + S * prec
        cov = np.linalg.inv(Lam)
        rhs = prior_prec * spec.centre + np.einsum("kij,kj->ki", prec, u.sum(axis=1))
        m = np.einsum("kij,kj->ki", cov, rhs)
        mu = m + np.einsum("kij,kj->ki", np.linalg.cholesky(cov), rng.standard_normal((C, p)))
        r = u - mu[:, None]
        psi = np.einsum("ksi,ksj->kij", r, r) + 2 * nu * (1.0 / a)[:, :, None] * np.eye(p)[None]
        Sigma = _inv_wishart(nu + p - 1 + S, psi, rng)
        a = _inv_gamma(0.5 * (nu + p), nu * np.diagonal(np.linalg.inv(Sigma), axis1=1, axis2=2)
                       + 1.0 / spec.scale**2, rng)
        return mu, Sigma, a, w
    var = np.diagonal(Sigma, axis1=1, axis2=2).copy()
    lam = prior_prec + (w / var[:, None]).sum(axis=1)
    m = (prior_prec * spec.centre + (w * u).sum(axis=1) / var) / lam
    mu = m + rng.standard_normal((C, p)) / np.sqrt(lam)
    r2 = (u - mu[:, None]) ** 2
    var = _inv_gamma(0.5 * (nu + S), nu / a + 0.5 * (w * r2).sum(axis=1), rng)
    a = _inv_gamma(0.5 * (nu + 1), nu / var + 1.0 / spec.scale**2, rng)
    if spec.student.any():
        wt = rng.gamma(0.5 * (NU_T + 1), 1.0 / (0.5 * (NU_T + r2 / var[:, None])))
        w = np.where(spec.student, wt, 1.0)
    Sigma = np.zeros((C, p, p))
    Sigma[:, np.arange(p), np.arange(p)] = var
    return mu, Sigma, a, w


class _ShiftMoves:
    """The :func:`_shift_move` of each weak parameter per sweep (none when not ``enabled``) and
    their step sizes.  Steps: per parameter, the sd of ``mu`` and of ``log sd`` over the second
    quarter of the burn-in, times a factor per block tuned towards 25% acceptance in the
    burn-in (then fixed, so the kernel is fixed after the burn-in)."""

    def __init__(self, enabled, weak, loc0, spec):
        self.enabled, self.spec = enabled, spec
        self.loc, self.scale = loc0.copy(), np.full(spec.p, 0.3)
        self.hist = []
        self._blocks(weak)

    def _blocks(self, weak):
        self.blocks = [np.array([j]) for j in np.flatnonzero(weak)] if self.enabled else []
        self.factor = [2.38 / math.sqrt(2 * len(b)) for b in self.blocks]
        self.n = [0] * len(self.blocks)
        self.acc = [0.0] * len(self.blocks)
        self.total = [[0.0, 0] for _ in self.blocks]

    def steps(self, C, rng):
        p = self.spec.p
        for b, f in zip(self.blocks, self.factor):
            d, eps = np.zeros((C, p)), np.zeros((C, p))
            d[:, b] = f * self.loc[b] * rng.standard_normal((C, len(b)))
            eps[:, b] = f * self.scale[b] * rng.standard_normal((C, len(b)))
            yield d, eps

    def record(self, k, took, after_burn):
        self.n[k] += 1
        self.acc[k] += took.mean()
        if after_burn:
            self.total[k][0] += took.mean()
            self.total[k][1] += 1

    def adapt(self, sweep, burn, mu, Sigma, within):
        self.hist.append((mu.copy(), 0.5 * np.log(np.diagonal(Sigma, axis1=1, axis2=2))))
        if sweep == burn // 2:  # weak parameters and steps from the burn-in so far
            m = np.concatenate([h[0] for h in self.hist[burn // 4:]])
            ls = np.concatenate([h[1] for h in self.hist[burn // 4:]])
            self.loc, self.scale = m.std(axis=0) + 1e-12, ls.std(axis=0) + 1e-3
            self._blocks(within > 0.25 * np.median(np.exp(2 * ls), axis=0))
        else:
            for k in range(len(self.blocks)):
                if self.n[k] == 20:  # towards 25% acceptance
                    self.factor[k] *= math.exp(self.acc[k] / self.n[k] - 0.25)
                    self.n[k], self.acc[k] = 0, 0.0

    def acceptance(self):
        rates = [t / n for t, n in self.total if n]
        return float(np.mean(rates)) if rates else None


def _shift_move(subs, z, ll, theta, u, mu, Sigma, a, spec, d, eps, rng):
    """Joint Metropolis move of the hyper-parameters and every subject along the non-centred
    coordinates ``eta = D^-1 (u - mu)`` (held fixed): ``mu' = mu + d``, ``sd' = sd e^eps``
    (``Sigma' = D Sigma D``, ``D = diag(e^eps)``), ``u' = mu' + D (u - mu)``, the other slots
    fixed in their z coordinates (a separable sampling map).  ``d``, ``eps`` (C, p): symmetric
    random steps (zero for the parameters not moved).  In the coordinates (mu, Sigma, u, other
    z) the population density ratio is ``|D|^-S`` and the map's Jacobian ``|D|^(S + p + 1)``
    (``|D|^S`` from the subjects, ``prod_i<=j e^(eps_i + eps_j)`` from Sigma's entries; for an
    independent population each variance alone gives ``e^(2 eps_j)``), so the ratio is
    likelihood ratio x hyper-prior ratio (mu normal; Sigma | a inverse-Wishart, variance | a
    inverse-gamma) x ``|D|^(p + 1)`` (correlated) or ``e^(2 sum eps)`` (independent).
    Returns (accepted (C,), z, ll, mu, Sigma, theta)."""
    C, S, p = u.shape
    g = np.exp(eps)
    mu_new = mu + d
    u_new = mu_new[:, None] + g[:, None] * (u - mu[:, None])
    Sigma_new = Sigma * g[:, :, None] * g[:, None, :]
    nu = NU_HYPER
    prior_mu = lambda m: -0.5 * (((m - spec.centre) / (2 * spec.scale)) ** 2).sum(axis=1)  # noqa: E731
    if spec.correlated:
        df = nu + p - 1
        psi = 2 * nu / a  # the diagonal of the inverse-Wishart scale

        def lp_sigma(Sg):
            _, logdet = np.linalg.slogdet(Sg)
            return -0.5 * (df + p + 1) * logdet - 0.5 * (psi * np.diagonal(np.linalg.inv(Sg), axis1=1, axis2=2)).sum(1)
        log_jac = (p + 1) * eps.sum(axis=1)
    else:
        def lp_sigma(Sg):  # InvGamma(nu/2, nu/a) per variance
            v = np.diagonal(Sg, axis1=1, axis2=2)
            return (-(0.5 * nu + 1) * np.log(v) - nu / (a * v)).sum(axis=1)
        log_jac = 2 * eps.sum(axis=1)
    th = theta.copy()
    with np.errstate(over="ignore"):
        th[..., spec.index] = np.where(spec.log, np.exp(np.clip(u_new, -700, 700)), u_new)
    z_new = subs.to_z(th)
    th, _ = subs.transform(z_new)
    ok = np.all(np.isfinite(z_new), axis=-1)[..., None]
    ll_new = subs.log_likelihood(np.where(ok, th, np.nan))
    with np.errstate(invalid="ignore"):
        log_r = (prior_mu(mu_new) - prior_mu(mu) + lp_sigma(Sigma_new) - lp_sigma(Sigma) + log_jac
                 + (ll_new - ll).sum(axis=1))
    take = np.log(rng.random(C)) < np.where(np.isfinite(log_r), log_r, -np.inf)
    z = np.where(take[:, None, None], z_new, z)
    ll = np.where(take[:, None], ll_new, ll)
    theta = np.where(take[:, None, None], th, theta)
    mu = np.where(take[:, None], mu_new, mu)
    Sigma = np.where(take[:, None, None], Sigma_new, Sigma)
    return take, z, ll, mu, Sigma, theta
