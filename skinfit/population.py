"""Population inference from per-subject fits, by importance reweighting of their samples.

Each subject ``i`` was fitted separately under a known prior ``pi_i``.  In each parameter's
sampling coordinate ``z`` (``log theta`` for a parameter with lower bound >= 0, else ``theta``)
the population model is ``z_i ~ Normal(mu, Sigma)`` with ``Sigma = diag(tau) Omega diag(tau)``
(``Omega`` = identity unless ``correlated=True``), i.e. log-normal populations for positive
parameters.  The likelihood of the hyper-parameters is estimated from each subject's draws
``z_is`` (Hogg, Myers & Bovy 2010, ApJ 725, 2166, eq. 9)::

    p(data | mu, Sigma)  ~  prod_i  (1/S) sum_s  Normal(z_is; mu, Sigma) / pi_i(z_is)

(``pi_i`` is the subject fit's prior of these parameters in the z coordinate, rebuilt from
the prior file saved in the fit), and the hyper-posterior is sampled with emcee through the
engine's :func:`skinfit.sampling.run_emcee`.

Hyper-priors (proper, and recorded in the result): with ``c_j`` and ``s_j`` the mean and sd of
the first subject's prior of parameter ``j`` in its z coordinate,
``mu_j ~ Normal(c_j, 2 s_j)``, ``tau_j ~ HalfNormal(s_j)`` and, when correlated,
``Omega ~ LKJ(eta=2)`` (sampled as independent Beta canonical partial correlations,
Lewandowski, Kurowicka & Joe 2009).

A subject's shrunk posterior (its posterior under the population rather than its own prior)
is drawn by resampling its draws with weights ``Normal(z_is; mu, Sigma) / pi_i(z_is)``, one
draw per hyper-posterior draw.  When the effective sample size of these weights (median over
hyper draws, ``(sum w)^2 / sum w^2``) is below ``min_ess`` (default 50) for a subject, the
reweighting rests on too few of its samples and a :class:`PopulationWarning` says so: refit
that subject with a higher ``ess`` target.
"""

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from .errors import ConvergenceWarning, InputError
from .fit import Fit, _priors_from_attrs, _slot_values, as_generator
from .posterior import _transform_for
from .sampling import run_emcee

__all__ = ["population", "PopulationResult", "PopulationWarning"]

_LKJ_ETA = 2.0


class PopulationWarning(UserWarning):
    """A subject's samples are too few for the importance reweighting."""


@dataclass
class PopulationResult:
    """Hyper-posterior draws and shrunk subject posteriors.

    ``mu``, ``tau``: (n, p) draws in the z coordinate; ``corr``: (n, p, p); ``shrunk``:
    {subject: (n, p) draws in natural units}; ``separate``: {subject: (S, p) natural-unit draws
    of the separate fit}; ``ess``: {subject: median importance ESS}.
    """

    parameters: list
    log: list  # per parameter: True when z = log(theta)
    subjects: list
    mu: np.ndarray
    tau: np.ndarray
    corr: np.ndarray
    shrunk: dict
    separate: dict
    ess: dict
    hyperpriors: dict
    sampler: dict = field(default_factory=dict)

    def population_draws(self):
        """Draws of the population mean, sd and median in natural units: dict name -> (n, p)."""
        if not any(self.log):
            return {"mean": self.mu, "sd": self.tau, "median": self.mu}
        lg = np.array(self.log)
        mean = np.where(lg, np.exp(self.mu + 0.5 * self.tau**2), self.mu)
        sd = np.where(lg, mean * np.sqrt(np.expm1(self.tau**2)), self.tau)
        return {"mean": mean, "sd": sd, "median": np.where(lg, np.exp(self.mu), self.mu)}

    def summary(self, prob=0.95):
        """Per parameter: population mean, sd and median (natural units), ``mu`` and ``tau``
        (z coordinate) and correlations: posterior median and central ``prob`` interval."""
        a = 0.5 * (1 - prob)
        rows = []
        draws = self.population_draws()
        for j, name in enumerate(self.parameters):
            coord = "log" if self.log[j] else "natural"
            items = [("mean", draws["mean"][:, j], "natural"), ("sd", draws["sd"][:, j], "natural"),
                     ("median", draws["median"][:, j], "natural"), ("mu", self.mu[:, j], coord),
                     ("tau", self.tau[:, j], coord)]
            for qty, x, c in items:
                lo, med, hi = np.quantile(x, [a, 0.5, 1 - a])
                rows.append({"parameter": name, "quantity": qty, "estimate": med, "lower": lo, "upper": hi,
                             "coordinate": c})
        p = len(self.parameters)
        for j in range(p):
            for k in range(j + 1, p):
                lo, med, hi = np.quantile(self.corr[:, j, k], [a, 0.5, 1 - a])
                rows.append({"parameter": f"{self.parameters[j]},{self.parameters[k]}", "quantity": "corr",
                             "estimate": med, "lower": lo, "upper": hi, "coordinate": "z"})
        return pd.DataFrame(rows)

    def subject_summary(self, prob=0.95):
        """Per subject and parameter: separate-fit and shrunk posterior median and interval."""
        a = 0.5 * (1 - prob)
        rows = []
        for s in self.subjects:
            for j, name in enumerate(self.parameters):
                sep = np.quantile(self.separate[s][:, j], [a, 0.5, 1 - a])
                shr = np.quantile(self.shrunk[s][:, j], [a, 0.5, 1 - a])
                rows.append({"subject": s, "parameter": name, "separate": sep[1], "separate_lower": sep[0],
                             "separate_upper": sep[2], "shrunk": shr[1], "shrunk_lower": shr[0],
                             "shrunk_upper": shr[2], "ess": self.ess[s]})
        return pd.DataFrame(rows)

    def to_datatree(self):
        """The hyper-posterior and the shrunk subject posteriors as an ArviZ DataTree."""
        import arviz as az

        draws = self.population_draws()
        post = {"mu": self.mu, "tau": self.tau, "pop_mean": draws["mean"], "pop_sd": draws["sd"],
                "theta": np.stack([self.shrunk[s] for s in self.subjects], axis=1)}
        post = {k: v[None] for k, v in post.items()}
        dims = {k: ["parameter"] for k in ("mu", "tau", "pop_mean", "pop_sd")} | {"theta": ["subject", "parameter"]}
        if len(self.parameters) > 1:
            post["corr"] = self.corr[None]
            dims["corr"] = ["parameter", "parameter_b"]
        coords = {"parameter": self.parameters, "parameter_b": self.parameters, "subject": self.subjects}
        attrs = {"hyperpriors": repr(self.hyperpriors), "importance_ess": repr(self.ess),
                 "coordinates": repr(dict(zip(self.parameters, ["log" if g else "natural" for g in self.log])))}
        return az.from_dict({"posterior": post}, dims=dims, coords=coords, attrs={"/": attrs})


def _subject_draws(fit, parameters, n_draws, rng):
    """(z draws (n, p), log prior density of z (n,), natural draws, log flags, priors) of one fit."""
    slots = {s["name"]: s for s in fit.attr("slots")}
    priors = _priors_from_attrs(fit.attrs)
    post = fit.group("posterior")
    cols, logp, logs, used = [], 0.0, [], []
    for name in parameters:
        if name not in slots:
            raise InputError(f"fit of {fit.model_id} on {fit.dataset_id}", f"no parameter {name!r} "
                             f"(sampled: {', '.join(slots)})", field="parameters")
        prior = priors[slots[name]["base"]]
        theta = _slot_values(post, slots[name])
        is_log = slots[name].get("transform", _transform_for(prior)) == "log"  # as the fit sampled it
        z = np.log(theta) if is_log else theta
        logp = logp + prior.logpdf(theta) + (z if is_log else 0.0)
        cols.append(z)
        logs.append(is_log)
        used.append(prior)
    z = np.column_stack(cols)
    pick = np.sort(rng.choice(len(z), size=min(n_draws, len(z)), replace=False))
    nat = np.where(logs, np.exp(z), z)
    return z[pick], np.asarray(logp)[pick], nat, logs, used


def _cholesky_corr(y, p):
    """Cholesky factors (k, p, p) of correlation matrices from unconstrained CPCs y (k, p(p-1)/2),
    and the log-density of the LKJ(eta) prior in the y coordinates (Jacobian included)."""
    k = len(y)
    L = np.zeros((k, p, p))
    L[:, 0, 0] = 1.0
    cpc = np.tanh(y)
    logd = np.zeros(k)
    m = 0
    for i in range(1, p):
        rem = np.ones(k)
        for j in range(i):
            b = _LKJ_ETA + (p - 2 - j) / 2.0
            logd += b * np.log1p(-cpc[:, m] ** 2)
            L[:, i, j] = cpc[:, m] * np.sqrt(rem)
            rem = rem - L[:, i, j] ** 2
            m += 1
        L[:, i, i] = np.sqrt(rem)
    return L, logd


class _HyperPosterior:
    """log p(mu, log tau, CPCs | all subjects), vectorised over walkers (k, d)."""

    def __init__(self, z, logprior, centre, spread, correlated):
        self.z = z  # (N, S, p)
        self.logprior = logprior  # (N, S)
        self.centre, self.spread, self.correlated = centre, spread, correlated
        self.p = z.shape[-1]

    def unpack(self, h):
        p = self.p
        mu, tau = h[:, :p], np.exp(h[:, p:2 * p])
        if self.correlated and p > 1:
            L, log_lkj = _cholesky_corr(h[:, 2 * p:], p)
        else:
            L, log_lkj = np.broadcast_to(np.eye(p), (len(h), p, p)), np.zeros(len(h))
        return mu, tau, L, log_lkj

    def log_normal(self, h, z):
        """log Normal(z; mu, Sigma) for each walker: z (..., p) -> (k, ...)."""
        mu, tau, L, _ = self.unpack(h)
        chol = tau[:, :, None] * L  # Cholesky of Sigma
        inv = np.linalg.inv(chol)
        flat = z.reshape(-1, self.p)
        y = (flat[None] - mu[:, None, :]) @ np.swapaxes(inv, 1, 2)  # (k, m, p) whitened
        logdet = np.log(np.abs(np.diagonal(chol, axis1=1, axis2=2))).sum(axis=1)
        out = -0.5 * (y**2).sum(-1) - logdet[:, None] - 0.5 * self.p * np.log(2 * np.pi)
        return out.reshape((len(h),) + z.shape[:-1])

    def log_hyperprior(self, h):
        mu, tau, _, log_lkj = self.unpack(h)
        lp = -0.5 * (((mu - self.centre) / (2 * self.spread)) ** 2).sum(1)
        lp += (-0.5 * (tau / self.spread) ** 2 + np.log(tau)).sum(1)  # half-normal + Jacobian of log
        return lp + log_lkj

    def __call__(self, h):
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            a = self.log_normal(h, self.z) - self.logprior[None]
            m = a.max(axis=2, keepdims=True)
            ll = (m[..., 0] + np.log(np.exp(a - m).sum(axis=2))).sum(1)  # logsumexp over draws
            out = self.log_hyperprior(h) + ll
        return np.where(np.isfinite(out), out, -np.inf)


def population(fits, parameters, *, correlated=False, rng=None, n_draws=1000, min_ess=50,
               ess_target=1000, max_steps=20000):
    """Infer the population distribution of ``parameters`` from separate per-subject fits.

    Parameters
    ----------
    fits : mapping label -> Fit, list of Fit, or the folder of a ``fit --by`` run
        One fit per subject (or condition), all of the same model.
    parameters : str or list of str
        Sampled parameters (slot names, e.g. ``"mu"`` or ``"alpha[25]"``).
    correlated : bool
        Multivariate normal population with an LKJ(2) prior on the correlations.
    rng : int, None or numpy.random.Generator
        The one source of randomness.
    n_draws : int
        Draws per subject used in the reweighting (a random subset without replacement).
    min_ess : float
        Warn when a subject's median importance-weight ESS falls below this.
    ess_target, max_steps
        Convergence target and step cap of the hyper-posterior emcee run.

    Returns
    -------
    PopulationResult
        ``.summary()`` (population mean/sd/median with 95% intervals in natural units),
        ``.subject_summary()``, ``.to_datatree()``.
    """
    rng = as_generator(rng)
    if isinstance(fits, (str, Path)):
        from .groups import load_groups

        fits = load_groups(fits)
    if not isinstance(fits, dict):
        fits = {f.dataset_id: f for f in fits}
    if len(fits) < 2 or not all(isinstance(f, Fit) for f in fits.values()):
        raise InputError("population", f"expected at least two Fit objects (got {len(fits)})", field="fits")
    parameters = [parameters] if isinstance(parameters, str) else list(parameters)
    models = {f.model_id for f in fits.values()}
    if len(models) > 1:
        raise InputError("population", f"fits of different models ({', '.join(sorted(models))})", field="fits")
    subjects = list(fits)
    zs, lps, separate, first = [], [], {}, None
    for s in subjects:
        z, lp, nat, logs, used = _subject_draws(fits[s], parameters, n_draws, rng)
        zs.append(z)
        lps.append(lp)
        separate[s] = nat
        first = first or (logs, used)
    S = min(len(z) for z in zs)
    z = np.stack([x[:S] for x in zs])
    logprior = np.stack([x[:S] for x in lps])
    logs, used = first  # hyper-priors from the first subject's prior, in z coordinates
    u = (np.arange(2000) + 0.5) / 2000
    qs = [np.log(pr.ppf(u)) if lg else pr.ppf(u) for pr, lg in zip(used, logs)]
    centre = np.array([q.mean() for q in qs])
    spread = np.array([q.std() for q in qs])
    hyper = {name: {"mu": f"normal(loc={c:.4g}, scale={2 * s_:.4g})", "tau": f"halfnormal(scale={s_:.4g})",
                    "coordinate": "log" if lg else "natural"}
             for name, c, s_, lg in zip(parameters, centre, spread, logs)}
    if correlated and len(parameters) > 1:
        hyper["correlation"] = f"LKJ(eta={_LKJ_ETA:g}) via Beta canonical partial correlations"
    target = _HyperPosterior(z, logprior, centre, spread, correlated)

    p = len(parameters)
    means = z.mean(axis=1)
    tau0 = np.maximum(means.std(axis=0), 0.2 * spread)
    d = 2 * p + (p * (p - 1) // 2 if correlated else 0)
    x0 = np.concatenate([means.mean(axis=0), np.log(tau0), np.zeros(d - 2 * p)])
    nwalkers = max(32, 4 * d)
    p0 = x0 + 0.05 * rng.standard_normal((nwalkers, d))
    run = run_emcee(target, p0, rng, ess_target=ess_target, max_steps=max_steps)
    if not run.converged:
        warnings.warn("population hyper-posterior not converged: " + "; ".join(run.reasons),
                      ConvergenceWarning, stacklevel=2)
    h = run.chain.reshape(-1, d)
    mu, tau, L, _ = target.unpack(h)
    corr = L @ np.swapaxes(L, 1, 2)

    shrunk, ess = {}, {}
    for i, s in enumerate(subjects):
        logw = np.concatenate([target.log_normal(h[k:k + 500], z[i]) for k in range(0, len(h), 500)])
        logw = logw - logprior[i][None]
        w = np.exp(logw - logw.max(axis=1, keepdims=True))
        ess[s] = float(np.median(w.sum(1) ** 2 / (w**2).sum(1)))
        pick = np.argmax(logw + rng.gumbel(size=logw.shape), axis=1)  # one draw per hyper draw
        shrunk[s] = np.where(logs, np.exp(z[i][pick]), z[i][pick])
        if ess[s] < min_ess:
            warnings.warn(f"subject {s}: importance-weight effective sample size {ess[s]:.0f} < {min_ess} "
                          f"(of {S} draws): its samples are too few for the population reweighting; refit it "
                          f"with a higher ess target", PopulationWarning, stacklevel=2)
    sampler = {"converged": run.converged, "n_steps": run.n_steps, "tau": run.tau.tolist(),
               "reasons": list(run.reasons), "draws_per_subject": S}
    return PopulationResult(parameters, list(logs), subjects, mu, tau, corr, shrunk, separate, ess, hyper,
                            sampler)
