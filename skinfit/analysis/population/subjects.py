"""The subjects of the Gibbs sampler (:mod:`skinfit.analysis.population.hierarchical`): their
Posteriors, the Gaussian summaries of their separate fits and the prior pieces the population
replaces; their log-likelihoods in one forward call where that reproduces each subject's own."""

import math

import numpy as np

from skinfit.io.priors import LOG_DENSITIES
from skinfit.posterior import standardised_squares

__all__ = ["Subjects"]


class Subjects:
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
    the same constants and normal or log-normal noise without known per-row standard errors
    (:attr:`skinfit.posterior.Posterior.se`); :meth:`Subjects.use_stacked` checks
    the result against the subjects' own likelihoods before it is used."""

    def __init__(self, posts):
        first = posts[0]
        try:
            same = all(p.model is first.model or p.model.id == first.model.id for p in posts) and all(
                p.constants.keys() == first.constants.keys()
                and all(np.array_equal(p.constants[k], first.constants[k]) for k in first.constants) for p in posts)
        except (TypeError, ValueError):
            same = False
        # known per-row standard errors (Posterior.se): no sufficient statistics, each subject's own likelihood
        if not same or any(p.se for p in posts) or any(
                p.noise[o] not in ("normal", "lognormal") for p in posts for o in p.observables) or any(
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
