"""The vectorised log-posterior of a model, its priors and a dataset.

Knows nothing about skin: it maps an ensemble of sampled vectors ``z`` (shape (k, d), an
unconstrained space) to natural parameters, calls the model's forward function once for the
whole ensemble, and adds the noise log-likelihood and the normalised log-prior.
"""

import math
from dataclasses import dataclass, replace

import numpy as np

from skinfit.errors import InputError
from skinfit.io.data import check_units
from skinfit.io.forward_check import check_forward, check_quantiles, forward_error, undefined_hint
from skinfit.io.known_se import covariate_se, observable_se
from skinfit.io.labels import level_labels, noise_parameter_names, noise_suffix
from skinfit.io.models import resolve_constants, resolve_forward, resolve_noise, resolve_split
from skinfit.io.priors import check_physical, check_priors_for, prior_groups

__all__ = ["Posterior", "Slot"]

_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class Slot:
    """One sampled scalar: a parameter, or one level of a split parameter."""

    name: str  # display name, e.g. "alpha[25]"
    base: str  # parameter name, e.g. "alpha"
    level: str | None
    prior: object
    transform: str  # "log" | "identity" | "shift_log" | "product" (see Posterior._special_transforms)
    lo: float
    hi: float

    @property
    def log_scale(self):
        """Sampled on a log scale (plain, shifted or as a product): a positive parameter."""
        return self.transform != "identity"


def _transform_for(prior, linear=False):
    """Sampling coordinate: log for non-negative parameters (products the data pin down become
    linear ridges, which emcee's affine-invariant moves handle well), else the identity; a card
    lists in ``[sampling] linear`` positive parameters whose *sums* the data pin down.
    Bounds stay hard: the prior is -inf outside them."""
    return "log" if prior.lower >= 0 and not linear else "identity"


def standardised_squares(zbar, ssw, counts, mu, sigma, lognormal):
    """sum over the rows sharing a distinct covariate row of ((z - m) / sigma)^2, from their
    sufficient statistics: (ssw + counts (zbar - m)^2) / sigma^2, with z = y, m = mu (normal
    noise) or z = log y, m = log mu (log-normal).  ``zbar``, ``ssw``, ``counts`` (n_unique,): mean
    of z, sum of squares about it, number of rows; ``mu``, ``sigma`` (k, n_unique) -> (k, n_unique)."""
    m = np.log(mu) if lognormal else mu
    d = zbar - m
    return (ssw + counts * d * d) / (sigma * sigma)


def _take(theta, j):
    """A parameter's values in ``theta`` (k, d), from its index ``j`` (an entry of
    ``Posterior._param_index``): (k, 1) for a column, (k, n) for a per-row gather index (a
    parameter split by a grouping column)."""
    return theta[:, j:j + 1] if isinstance(j, int) else theta[:, j]


class Posterior:
    """log p(z | data) for an ensemble of walkers, with everything needed to build it.

    Parameters
    ----------
    model : skinfit.Model
    priors : skinfit.PriorSet
        Must give a prior for every model parameter and every noise parameter.
    dataset : skinfit.Dataset
    split : mapping parameter -> grouping column (or list of columns), optional
        Parameters sampled once per level of the column(s); others are shared.
    noise : str or mapping observable -> str, optional
        ``normal`` (default, or the card's), ``student_t`` or ``lognormal``.
    constants : mapping, optional
        Overrides of the model card's fixed constants.

    A dataset column ``<observable>_se`` (:mod:`skinfit.io.known_se`) adds a known variance per
    row: noise sd sqrt(sigma^2 + se_i^2) (:meth:`noise_scale`), sigma the extra scatter.
    """

    CHUNK = 256  # parameter vectors per forward call (memory bound)
    #: (parameter vector, distinct row) cells per forward call: calls on more are split into
    #: equal blocks, so that the (k, rows) temporaries stay in cache (docs/design/sampling.md).
    EVAL_CELLS = 49152

    def __init__(self, model, priors, dataset, *, split=None, noise=None, constants=None):
        self.model, self.priors, self.dataset = model, priors, dataset
        where = f"fit of {model.id} on {dataset.id}"
        check_priors_for(priors, model)
        check_units(dataset, model)
        frame = dataset.frame
        self.observables = tuple(o.name for o in model.observables if o.name in frame.columns)
        if not self.observables:
            raise InputError(dataset.path, f"no observable of model {model.id!r} in the data "
                             f"(expected a column {' or '.join(map(repr, model.observable_names))})")
        self.noise = noise = resolve_noise(model, self.observables, noise, where)
        self.constants = resolve_constants(model, constants, where)

        # covariates and observed values (SI, float arrays of shape (n,))
        self.x = {}
        for cov in model.covariates:
            if cov.name not in frame.columns:
                if cov.optional:
                    self.x[cov.name] = np.full(len(frame), np.nan)
                    continue
                raise InputError(dataset.path, f"missing covariate column {cov.name!r} [{cov.unit}] "
                                 f"needed by model {model.id!r}")
            values = frame[cov.name].to_numpy(dtype=float)
            if np.isnan(values).any() and not cov.optional:
                row = int(np.argmax(np.isnan(values))) + 1
                raise InputError(dataset.path, f"covariate {cov.name!r} is missing, and model "
                                 f"{model.id!r} needs it at every row", row=row)
            self.x[cov.name] = values
        self.y = {o: frame[o].to_numpy(dtype=float) for o in self.observables}
        for o in self.observables:
            if np.isnan(self.y[o]).any():
                row = int(np.argmax(np.isnan(self.y[o]))) + 1
                raise InputError(dataset.path, f"observable {o!r} is missing", row=row)
            if noise[o] == "lognormal" and (self.y[o] <= 0).any():
                row = int(np.argmax(self.y[o] <= 0)) + 1
                raise InputError(dataset.path, f"observable {o!r} must be > 0 for a log-normal "
                                 f"likelihood (got {self.y[o][row - 1]:g})", row=row)
        self.n = len(frame)
        self._logy = {o: np.log(self.y[o]) for o in self.observables if noise[o] == "lognormal"}
        self.se = observable_se(dataset, model, self.observables)  # observable -> known per-row se (n,), SI
        self._se2 = {o: (se / self.y[o] if noise[o] == "lognormal" else se) ** 2 for o, se in self.se.items()}
        self.covariate_se = covariate_se(dataset, model)  # reported, not modelled
        self._sum_logy = {o: float(v.sum()) for o, v in self._logy.items()}

        # which sampled slot feeds each parameter
        self.split = resolve_split(model, split, dataset, where)
        self.noise_names = tuple(noise_parameter_names(self.observables, noise))
        needed = list(model.parameter_names) + list(self.noise_names)
        missing = [p for p in needed if p not in priors]
        if missing:
            raise InputError(priors.path or "priors", f"no prior for {', '.join(missing)} "
                             f"(model {model.id!r} needs priors for {', '.join(needed)})")
        check_physical(model, priors, self.noise_names)
        slots, self._param_index, self.levels = [], {}, {}
        for pname in needed:
            prior = priors[pname]
            if pname in self.split:
                labels = level_labels(frame, self.split[pname], dataset)
                levels = list(dict.fromkeys(labels))  # order of appearance
                codes = np.array([levels.index(v) for v in labels])
                self.levels[pname] = (self.split[pname], tuple(levels))
                first = len(slots)
                for lev in levels:
                    slots.append(Slot(f"{pname}[{lev}]", pname, lev, prior,
                                      _transform_for(prior, pname in model.linear),
                                      prior.lower, prior.upper))
                self._param_index[pname] = first + codes  # (n,) gather index
            else:
                self._param_index[pname] = len(slots)
                slots.append(Slot(pname, pname, None, prior, _transform_for(prior, pname in model.linear),
                                  prior.lower, prior.upper))
        self._unique_rows()
        self.slots = self._special_transforms(model, slots)
        self.names = tuple(s.name for s in self.slots)
        self.ndim = len(self.slots)
        self._lo = np.array([s.lo for s in self.slots])
        self._hi = np.array([s.hi for s in self.slots])
        self._prior_groups = prior_groups([s.prior for s in self.slots])
        self._log_norm = float(sum(s.prior._log_norm for s in self.slots))
        self.counts = {"evaluations": 0, "outside_prior": 0, "outside_support": 0}
        self._check_forward()

    def _check_forward(self):
        """The forward function on a few prior quantiles (no random draw) at the data's distinct
        rows, checked against its contract (skinfit.io.forward_check) before any work starts."""
        theta = self.prior_transform(check_quantiles(self.ndim))
        params = {p: _take(theta, j) for p, j in self._param_index_u.items()}
        with np.errstate(all="ignore"):  # what the function computes is checked, not how
            check_forward(self.model, params, self._xu, self.constants, self.observables,
                          rows=self._first + 1, points=[dict(zip(self.names, t)) for t in theta])

    def _unique_rows(self):
        """Repeated measurements: the forward model runs once per distinct row (covariates and
        levels of split parameters), and the normal / log-normal likelihood of a row group
        needs only its count, mean and within-group sum of squares:
        ``sum_i (y_i - mu)^2 = SS_within + n_u (ybar_u - mu)^2`` exactly (no cancellation)."""
        cols = [np.ascontiguousarray(v, dtype=float).view(np.int64) for v in self.x.values()]
        cols += [np.asarray(j) for j in self._param_index.values() if not isinstance(j, int)]
        keys = np.column_stack(cols) if cols else np.zeros((self.n, 1), dtype=np.int64)
        _, first, inverse, counts = np.unique(keys, axis=0, return_index=True, return_inverse=True,
                                              return_counts=True)
        order = np.argsort(first)  # groups in order of first appearance
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        self._first, self._inverse = first[order], rank[inverse.reshape(-1)]
        self._counts = counts[order].astype(float)
        self.n_unique = len(self._first)
        self._xu = {c: v[self._first] for c, v in self.x.items()}
        self._param_index_u = {p: j if isinstance(j, int) else j[self._first] for p, j in self._param_index.items()}
        self._zbar, self._ssw = {}, {}
        for o in self.observables:
            z = self._logy[o] if o in self._logy else self.y[o]
            zbar = np.bincount(self._inverse, z, self.n_unique) / self._counts
            self._zbar[o] = zbar
            self._ssw[o] = np.bincount(self._inverse, (z - zbar[self._inverse]) ** 2, self.n_unique)

    # ---- transforms ---------------------------------------------------------------------
    def _special_transforms(self, model, slots):
        """Apply the card's ``[sampling]`` reparameterisations where they are valid.

        ``shift``: a positive parameter sampled as ``log(theta + c)``, ``c`` a function of the
        constants (a quantity the data see only through ``theta + c``, e.g. a layer stack).
        ``product``: a positive parameter sampled as ``theta * prod(partner**power)`` in natural
        units (a product the data pin down and that enters the prediction as a *sum*), partners
        being shared log-sampled parameters.  ``shear``: a log-sampled parameter sampled as
        ``log(theta) - offset(other parameters)``.  All three have a closed-form Jacobian
        (:meth:`log_jacobian`).  Declarations whose conditions fail (a split parameter, a prior
        reaching <= 0) fall back to the plain log/identity coordinate.
        """
        shared = {p: j for p, j in self._param_index.items() if isinstance(j, int)}
        shift = np.zeros(len(slots))
        for pname, ref in model.shift.items():
            c = float(resolve_forward(ref, model.path, "shift")(self.constants))
            for j, slot in enumerate(slots):
                if slot.base == pname and slot.transform == "log" and c > 0 and slot.lo + c > 0:
                    slots[j] = replace(slot, transform="shift_log")
                    shift[j] = c
        self._product = []
        for pname, partners in model.product.items():
            j = shared.get(pname)
            cols = [shared.get(q) for q in partners]
            if j is None or slots[j].transform != "log" or any(k is None or slots[k].transform != "log" for k in cols):
                continue
            slots[j] = replace(slots[j], transform="product")
            self._product.append((j, np.array(cols), np.array([float(v) for v in partners.values()])))
        self._expo = np.array([s.transform == "log" for s in slots])
        self._shifted = np.flatnonzero(shift)
        self._shift = shift[self._shifted]  # theta = c*expm1(z - log c): exactly 0 at z = log c
        self._log_shift = np.log(self._shift)
        self._shear = tuple((j, resolve_forward(ref, model.path, "shear")) for pname, ref in model.shear.items()
                            if (j := shared.get(pname)) is not None and slots[j].transform == "log")
        self._sheared = {slots[j].base for j, _ in self._shear}
        return tuple(slots)

    def _shear_inputs(self, theta):
        return {name: theta[:, idx] for name, idx in self._param_index.items()
                if isinstance(idx, int) and name not in self._sheared}

    def _transform(self, z):
        """Natural parameters and log |d theta / d z| from sampled coordinates: ((k, d), (k,))."""
        z = np.atleast_2d(np.asarray(z, dtype=float))
        theta = z.copy()
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            theta[:, self._expo] = np.exp(z[:, self._expo])
            theta[:, self._shifted] = self._shift * np.expm1(z[:, self._shifted] - self._log_shift)
            log_jac = z[:, self._expo].sum(axis=1) + z[:, self._shifted].sum(axis=1)
            for j, cols, powers in self._product:
                log_partners = np.log(theta[:, cols]) @ powers
                theta[:, j] = z[:, j] * np.exp(-log_partners)
                log_jac = log_jac - log_partners
            if self._shear:
                p = self._shear_inputs(theta)
                for j, func in self._shear:
                    offset = func(p, self.constants)
                    theta[:, j] = np.exp(z[:, j] + offset)
                    log_jac = log_jac + offset
        return theta, log_jac

    def to_theta(self, z):
        """Natural parameters (k, d) from sampled coordinates z (k, d)."""
        return self._transform(z)[0]

    def to_z(self, theta):
        """Sampled coordinates (k, d) of natural parameters (k, d)."""
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        z = theta.copy()
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            z[:, self._expo] = np.log(theta[:, self._expo])
            z[:, self._shifted] = self._log_shift + np.log1p(theta[:, self._shifted] / self._shift)
            for j, cols, powers in self._product:
                z[:, j] = theta[:, j] * np.exp(np.log(theta[:, cols]) @ powers)
            if self._shear:
                p = self._shear_inputs(theta)
                for j, func in self._shear:
                    z[:, j] = np.log(theta[:, j]) - func(p, self.constants)
        return z

    def box_bounds(self):
        """Bounds (lower, upper) of the sampled coordinates, each (d,): the prior bounds mapped
        coordinate by coordinate (log, shifted log, identity); -inf and inf where the range of a
        coordinate depends on other parameters (product, shear), which the density alone keeps."""
        z = self.to_z(np.array([self._lo, self._hi]))
        free = [j for j, _, _ in self._product] + [j for j, _ in self._shear]
        z[0, free], z[1, free] = -np.inf, np.inf
        return z[0], z[1]

    def log_jacobian(self, z):
        """log |d theta / d z| of the sampling map, shape (k,)."""
        return self._transform(z)[1]

    # ---- densities ----------------------------------------------------------------------
    def unpack(self, theta):
        """Mapping parameter -> (k, 1) or (k, n) array for the forward function."""
        theta = np.atleast_2d(theta)
        return {p: _take(theta, j) for p, j in self._param_index.items()}

    def log_prior(self, theta):
        """Normalised log prior, (k,): one vectorised closed form per distribution family."""
        theta = np.atleast_2d(theta)
        inside = ((theta >= self._lo) & (theta <= self._hi)).all(axis=1)
        total = np.full(len(theta), -self._log_norm)
        with np.errstate(divide="ignore", invalid="ignore"):
            for logpdf, cols, args in self._prior_groups:
                total += logpdf(theta[:, cols], args, None, None).sum(axis=1)
        return np.where(inside, total, -np.inf)

    def _evaluate(self, theta, pointwise, predict=True):
        """:meth:`_evaluate_block` over equal blocks of at most ``CHUNK`` parameter vectors
        and :attr:`EVAL_CELLS` / distinct rows (at least 16).

        Keeps the forward model's arrays in cache, and bounds memory where a model's forward
        function works on larger arrays than (k, n) (the ultrasonic period average with a
        parameter split by a column takes its per-row values to every quadrature node).
        """
        k = len(theta)
        most = min(self.CHUNK, max(16, self.EVAL_CELLS // self.n_unique))
        if k <= most:
            return self._evaluate_block(theta, pointwise, predict)
        size = math.ceil(k / math.ceil(k / most))
        ll, pred, valid = {}, {}, np.empty(k, dtype=bool)
        for i in range(0, k, size):
            part = self._evaluate_block(theta[i:i + size], pointwise, predict)
            for out, values in zip((ll, pred), part[:2]):
                for o, v in values.items():
                    if o not in out:
                        out[o] = np.empty((k,) + v.shape[1:])
                    out[o][i:i + len(v)] = v
            valid[i:i + size] = part[2]
        return ll, pred, valid

    def _evaluate_block(self, theta, pointwise, predict=True):
        """Forward model + noise log-likelihood: (ll, pred, valid).

        ``ll`` maps observable -> (k, n) pointwise values when ``pointwise``, else -> (k,)
        totals (the sampling hot path: the forward model and the normal / log-normal
        likelihood on distinct rows only, see :meth:`_unique_rows`); ``pred`` maps
        observable -> (k, n) predictions (empty unless ``predict`` or ``pointwise``: expanding
        to every row cost a quarter of a call on contact_area).
        """
        theta = np.atleast_2d(theta)
        k = len(theta)
        params = {p: _take(theta, j) for p, j in self._param_index_u.items()}
        pred_u, ok = self.model.forward(params, self._xu, self.constants)
        ok = np.asarray(ok)
        valid = ok.all(axis=-1) if ok.ndim == 2 else np.full(k, bool(ok.all()) if ok.ndim else bool(ok))
        if ok.ndim == 2 and ok.shape[0] != k:
            valid = np.broadcast_to(valid, (k,))
        ll, pred = {}, {}
        with np.errstate(divide="ignore", invalid="ignore"):  # once: entering it costs ~7 us
            for o in self.observables:
                mu_u = pred_u[o]
                if mu_u.shape != (k, self.n_unique):
                    mu_u = np.broadcast_to(mu_u, (k, self.n_unique))
                noise = self.noise[o]
                per_row = noise == "student_t" or o in self._se2  # no sufficient statistics
                if predict or pointwise or per_row:
                    pred[o] = mu_u[:, self._inverse]
                if not (pointwise or per_row):
                    sigma = params[f"sigma{self._suffix(o)}"]
                    ss = standardised_squares(self._zbar[o], self._ssw[o], self._counts, mu_u, sigma,
                                              noise == "lognormal").sum(axis=1)
                    log_sigma = (self.n * np.log(sigma[:, 0]) if sigma.shape[1] == 1
                                 else (self._counts * np.log(sigma)).sum(axis=1))
                    ll[o] = -0.5 * ss - log_sigma - 0.5 * self.n * _LOG_2PI - self._sum_logy.get(o, 0.0)
                else:
                    sigma = self.noise_scale(theta, o)
                    if noise == "lognormal":  # the log on distinct rows, then to every row
                        r = np.log(mu_u)[:, self._inverse]
                        np.subtract(self._logy[o], r, out=r)
                    else:
                        r = self.y[o] - pred[o]
                    r /= sigma
                    if noise == "student_t":
                        # here, not with the module: scipy (~0.2 s) only for Student-t noise (tests/test_population.py)
                        from scipy import special

                        nu = self._noise_param(theta, "nu", o)
                        value = (special.gammaln(0.5 * (nu + 1)) - special.gammaln(0.5 * nu)
                                 - 0.5 * np.log(nu * math.pi) - np.log(sigma) - 0.5 * (nu + 1) * np.log1p(r * r / nu))
                    else:
                        value = r
                        value *= value
                        value *= -0.5
                        value -= np.log(sigma) + 0.5 * _LOG_2PI
                        if noise == "lognormal":
                            value -= self._logy[o]
                    value = np.broadcast_to(value, (k, self.n))
                    ll[o] = value if pointwise else value.sum(axis=1)
                if not valid.all():
                    ll[o] = np.where(valid[:, None] if pointwise else valid, ll[o], -np.inf)
        return ll, pred, valid

    def impossible_rows(self, theta):
        """1-based data rows at which no parameter vector of ``theta`` (k, d) gives a valid,
        finite prediction (the model's support condition fails, or the forward model or the
        likelihood is not finite): rows that make every such draw impossible."""
        theta = np.atleast_2d(theta)
        k = len(theta)
        possible = np.zeros(self.n_unique, dtype=bool)
        for i in range(0, k, self.CHUNK):
            block = theta[i:i + self.CHUNK]
            params = {p: _take(block, j) for p, j in self._param_index_u.items()}
            with np.errstate(all="ignore"):
                pred_u, ok = self.model.forward(params, self._xu, self.constants)
                good = np.broadcast_to(np.asarray(ok, dtype=bool), (len(block), self.n_unique)).copy()
                for o in self.observables:
                    mu = np.broadcast_to(pred_u[o], good.shape)
                    good &= np.isfinite(mu) & ((mu > 0) if self.noise[o] == "lognormal" else True)
            possible |= good.any(axis=0)
        return (np.flatnonzero(~possible[self._inverse]) + 1).tolist()

    def pointwise(self, theta):
        """Pointwise log-likelihood: dict observable -> (k, n), the predictions, and validity.

        Rows of ``theta`` outside the physical support get -inf at every point.
        """
        theta = np.atleast_2d(theta)
        ll, pred, valid = self._evaluate(theta, True)
        k = len(theta)
        return ({o: np.broadcast_to(v, (k, self.n)) for o, v in ll.items()},
                {o: np.broadcast_to(v, (k, self.n)) for o, v in pred.items()}, valid)

    def simulate(self, theta, rng):
        """Simulated observations at each parameter vector: dict observable -> (k, n).

        The model's prediction plus a draw of its noise model (normal, Student-t, log-normal).
        Rows of ``theta`` outside the physical support raise ``ValueError``.  (A fit's result
        tree uses :meth:`replicate`, which also returns the pointwise log-likelihood.)
        """
        theta = np.atleast_2d(theta)
        _, pred, valid = self._evaluate(theta, False)
        self._require_valid(valid)
        out = self._noise(theta, rng)
        for o, eps in out.items():
            self._observe(eps, np.broadcast_to(pred[o], eps.shape), theta, o)
        return out

    def replicate(self, theta, rng):
        """Pointwise log-likelihood and one simulated data set per parameter vector:
        (ll, simulated), dicts observable -> (k, n), equal to :meth:`pointwise` and then
        :meth:`simulate` with the same ``rng`` state.

        For the result tree of a fit (thousands of draws x every row): evaluated in blocks of
        :attr:`BLOCK_CELLS` (draw, row) cells that stay in cache, writing straight into the two
        outputs, with no (draws, rows) prediction arrays.  Rows of ``theta`` outside the
        physical support raise ``ValueError``.
        """
        theta = np.atleast_2d(theta)
        k = len(theta)
        simulated = self._noise(theta, rng)  # drawn first and whole: the stream simulate() draws
        ll = {o: np.empty((k, self.n)) for o in self.observables}
        step = int(np.clip(self.BLOCK_CELLS // max(self.n, 1), 1, self.CHUNK))
        for i in range(0, k, step):
            block = theta[i:i + step]
            part, pred, valid = self._evaluate_block(block, True)
            self._require_valid(valid)
            for o in self.observables:
                ll[o][i:i + step] = part[o]
                self._observe(simulated[o][i:i + step], pred[o], block, o)
        return ll, simulated

    #: (draw, row) cells per block of :meth:`replicate` (1 MB of float64 per array).
    BLOCK_CELLS = 131072

    def _require_valid(self, valid):
        if not np.all(valid):
            raise ValueError(f"{int((~np.asarray(valid)).sum())} parameter vector(s) outside the physical support "
                             f"of {self.model.id}: {self.model.support}")

    def _noise(self, theta, rng):
        """Standardised noise draws, observable -> (k, n), in observable order (the order fixes
        the random stream): standard normal, or standard Student-t with each draw's nu."""
        out = {}
        for o in self.observables:
            if self.noise[o] == "student_t":
                nu = self._noise_param(theta, "nu", o)
                out[o] = rng.standard_t(np.broadcast_to(nu, (len(theta), self.n)))
            else:
                out[o] = rng.standard_normal((len(theta), self.n))
        return out

    def _observe(self, eps, mu, theta, o):
        """Standardised noise ``eps`` (k, n) turned into observations around predictions ``mu``
        of parameter vectors ``theta``, in place (these are (draws, rows) arrays)."""
        eps *= self.noise_scale(theta, o)
        if self.noise[o] == "lognormal":
            np.exp(eps, out=eps)
            eps *= mu
        else:
            eps += mu

    def noise_scale(self, theta, o):
        """The sd (scale, for Student-t) of observable ``o``'s noise in the likelihood's space
        (of log y for log-normal noise) at parameter vectors ``theta`` (k, d): sigma, (k, 1) or,
        split by a column, (k, n); with known per-row standard errors se_i, sqrt(sigma^2 + se_i^2)
        (k, n), se_i / y_i in place of se_i for log-normal noise (the delta method)."""
        sigma = self._noise_param(theta, "sigma", o)
        return np.sqrt(sigma * sigma + self._se2[o]) if o in self._se2 else sigma

    def _suffix(self, o):
        return noise_suffix(self.observables, o)

    def _noise_param(self, theta, kind, o):
        """Observable ``o``'s noise parameter ``kind`` (``sigma`` or ``nu``) in ``theta``, (k, 1)
        or, split by a column, (k, n)."""
        return _take(theta, self._param_index[f"{kind}{self._suffix(o)}"])

    def log_likelihood(self, theta):
        ll, _, _ = self._evaluate(np.atleast_2d(theta), False, predict=False)
        total = None
        for v in ll.values():
            total = v if total is None else total + v
        return total

    def log_density(self, theta):
        """log prior + log likelihood in natural parameters, (k,); -inf outside support."""
        theta = np.atleast_2d(theta)
        lp = self.log_prior(theta)
        inside = np.isfinite(lp)
        n_in = int(inside.sum())
        self.counts["evaluations"] += len(theta)
        self.counts["outside_prior"] += len(theta) - n_in
        if n_in == 0:
            return lp
        sub = theta if n_in == len(theta) else theta[inside]
        ll = self.log_likelihood(sub)
        self.counts["outside_support"] += int(np.isneginf(ll).sum())
        if np.isnan(ll).any():
            raise self._nan_error(sub[np.isnan(ll)][0])
        if n_in == len(theta):
            return lp + ll
        out = np.full(len(theta), -np.inf)
        out[inside] = lp[inside] + ll
        return out

    def _nan_error(self, theta):
        """ForwardError for a NaN log-likelihood at parameter vector ``theta`` (d,) met while
        fitting (MAP search or sampling), naming the data row and the prediction there: NaN
        where the forward function marks the model valid (it must say ok False there)."""
        with np.errstate(all="ignore"):
            ll, pred, _ = self._evaluate_block(theta[None], True)
        point = ", ".join(f"{name}={v:.6g}" for name, v in zip(self.names, theta))
        for o in self.observables:
            rows = np.flatnonzero(np.isnan(ll[o][0]))
            if len(rows):
                r, value = rows[0], pred[o][0, rows[0]]
                if np.isnan(value):
                    return forward_error(self.model, f"returned nan for {o!r} at data row {r + 1} with parameters "
                                                     f"{{{point}}}, a point it marks valid (ok True), while fitting: "
                                                     f"{undefined_hint(self.model)}")
                return forward_error(self.model, f"NaN log-likelihood for {o!r} at data row {r + 1} (prediction "
                                                 f"{value:g}) with parameters {{{point}}}, while fitting")
        return forward_error(self.model, f"NaN log-likelihood at parameters {{{point}}} while fitting")

    def __call__(self, z):
        """log posterior density of the sampled coordinates z (k, d), Jacobian included."""
        theta, log_jac = self._transform(z)
        density = self.log_density(theta)
        return np.where(density == -np.inf, -np.inf, density + log_jac)

    # ---- helpers for optimisers and nested sampling --------------------------------------
    def prior_transform(self, u):
        """Map unit-cube points (k, d) to natural parameters distributed as the prior."""
        u = np.atleast_2d(u)
        return np.column_stack([s.prior.ppf(u[:, j]) for j, s in enumerate(self.slots)])

    def sample_prior(self, size, rng):
        """``size`` draws from the prior, natural parameters (size, d)."""
        return self.prior_transform(rng.uniform(size=(size, self.ndim)))

    def prior_draw_in_support(self, rng, batch=64, max_batches=200):
        """One prior draw inside the model's physical support, natural parameters (d,): the
        first valid one of batches of ``batch`` prior draws (the truth of a simulation: SBC,
        the misfit check's calibration). RuntimeError after ``max_batches`` batches."""
        for _ in range(max_batches):
            theta = self.sample_prior(batch, rng)
            _, _, valid = self.pointwise(theta)
            if valid.any():
                return theta[int(np.argmax(valid))]
        raise RuntimeError(f"{self.model.id}: no prior draw inside the physical support in "
                           f"{batch * max_batches} tries ({self.model.support})")

    def describe(self):  # the fit's "setup" attribute
        return {"parameters": list(self.names), "observables": list(self.observables), "noise": dict(self.noise),
                "split": {p: list(c) for p, c in self.split.items()}, "n_rows": self.n} | (
            {"known_se": list(self.se)} if self.se else {})
