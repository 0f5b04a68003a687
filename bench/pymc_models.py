"""The benchmark posteriors as PyMC models (forward models in pytensor), for the NUTS row.

``build_pymc(post)`` returns a ``pymc.Model`` whose log density in natural parameters equals
``post.log_density(theta)`` of a skinfit :class:`~skinfit.posterior.Posterior`: the same forward
model (one pytensor function per model family, dispatched on ``post.model.id``), the same noise
model and constants, the same truncated and renormalised priors on the same bounds, split
parameters gathered per data row as ``post._param_index`` does, and the model's physical-support
condition as a ``pm.Potential`` that is -inf outside.  Variables are named exactly ``post.names``
(one scalar per slot; the levels of a split parameter are stacked and gathered per row).  With
``rows="distinct"`` the forward model runs on the distinct data rows only and the normal /
log-normal likelihood comes from per-group sufficient statistics, as skinfit's Posterior now
evaluates it (same density; default ``rows="all"``, the per-row model a PyMC user writes).

Gradients stay finite inside the support (NUTS needs them): a square root or cube root that may
meet 0, or a branch that is not taken, is guarded by the "double where" pattern (the untaken
side sees a harmless argument), never by a bare ``pt.switch`` whose untaken side has an infinite
derivative (0 * inf = NaN in the chain rule).

``check_pymc`` compares PyMC's compiled log density with skinfit's; ``run_pymc`` samples with
NUTS under the harness conventions of bench/common.py.

pytensor's default cast policy turns Python float constants that are exact in float32 (0.5, 2.0,
...) into float32, and PyMC builds some log densities from such constants (e.g. ``log(0.5)`` and
``sqrt(2)`` in the truncated normal): every function here builds and compiles under
:func:`float64_constants`, which makes them float64 (PyMC's log densities then agree with
scipy's to ~1e-16 rather than ~1e-9).
"""

import math
import time
import warnings
from pathlib import Path

import numpy as np

from skinfit.physics.ultrasonic import _bracket_series

try:  # imported as bench.pymc_models, or as pymc_models from a script in bench/
    from bench.common import PeakRSS, Result, diagnostics
    from bench.fused import ultrasonic_interpolation
except ImportError:
    from common import PeakRSS, Result, diagnostics
    from fused import ultrasonic_interpolation

__all__ = ["build_pymc", "check_pymc", "run_pymc", "float64_constants", "FORWARDS"]


def _f(v):
    """A float64 constant for pytensor (a Python float exact in float32 would become float32)."""
    return np.asarray(v, dtype="float64")


def float64_constants():
    """Context: pytensor casts Python float constants to float64 (``cast_policy='numpy+floatX'``)."""
    import pytensor

    return pytensor.config.change_flags(cast_policy="numpy+floatX")


# ---- forward models in pytensor: (p, x, c) -> (pred, logpred, ok) --------------------------
# p: parameter name -> scalar tensor (shared) or (n,) tensor (split, gathered per row);
# x: covariate name -> (n,) numpy array (SI); c: constants.  pred: observable -> (n,) tensor;
# logpred: observable -> log of the prediction where it is available in closed form (log-normal
# noise); ok: scalar bool tensor (or Python bool), False outside the physical support.

def _electroadhesion(p, x, c):
    """As bench_electroadhesion.run_pymc had it (numerically identical graph)."""
    import pytensor.tensor as pt

    fn, v2 = x["normal_force"], x["voltage"] ** 2
    t = c["d_sio2"] / c["eps_sio2"] + p["d_air"] / c["eps_air"] + c["d_sc"] / c["eps_sc"]
    dg = 0.5 * c["eps0"] * v2 / t
    k = 3.0 * np.pi * c["R"] * dg
    # sqrt(2*k*fn + k*k) with a finite gradient at 0 V (k = 0): sqrt(1) * 0 there
    root = pt.sqrt(2.0 * k * fn + k * k + (v2 == 0)) * (v2 > 0)
    a0 = np.pi * (3.0 * c["R"] / (4.0 * p["E_star"]) * (fn + k + root)) ** (2.0 / 3.0)
    b = p["tau0"] * (p["beta0"] + p["phi"] * dg)
    cc = b * a0 + p["alpha"] * fn
    disc = 1.0 + 4.0 * b * p["eta"] * cc
    ft = 2.0 * cc / (1.0 + pt.sqrt(pt.abs(disc)))
    ok = pt.all(disc >= 0) & pt.all(a0 - p["eta"] * ft**2 > 0)
    return {"tangential_force": ft}, {}, ok


def _textured_surface(p, x, c):
    """skinfit.physics.textured.textured_surface (analytic Hertz reading of the Biotribology 2019 paper)."""
    import pytensor.tensor as pt

    f = x["normal_force"]
    geo = [x[k] for k in ("asperity_radius", "asperity_height", "asperity_spacing")]
    missing = [np.isnan(g) for g in geo]
    flat = missing[0] & missing[1] & missing[2]
    ok = bool(((missing[0] == missing[1]) & (missing[1] == missing[2]) & (f > 0)).all())  # covariates only
    r_asp, h, lam = (np.where(m, 1.0, g) for m, g in zip(missing, geo))  # harmless fill
    f_safe = np.where(f > 0, f, 1.0)
    cs, cm = 1.0 - c["nu_skin"] ** 2, (1.0 - c["nu_m"] ** 2) / x["sample_modulus"]
    e1 = 1.0 / (cs / p["E_skin_micro"] + cm)
    a_ac = p["k_a"] * f_safe ** p["m_a"]
    pbar = f_safe / a_ac
    f_i = pbar * lam**2
    f_crit = (4.0 / 3.0) * e1 * np.sqrt(r_asp) * h**1.5
    frac = pt.clip(1.0 - (2.0 * f_crit / (3.0 * f_i)) ** 2, 0.0, 1.0)
    frac = pt.where(flat, 0.0, frac)
    one_minus = 1.0 - frac
    pos = one_minus > 0  # (always, short of underflow; guards sqrt's derivative at 0)
    p_asp = pbar * pt.where(pos, pt.sqrt(pt.where(pos, one_minus, 1.0)), 0.0)
    arg = 3.0 * p_asp * lam**2 * r_asp / (4.0 * e1)
    pos = arg > 0
    a_i = pt.where(pos, pt.where(pos, arg, 1.0) ** (1.0 / 3.0), 0.0)  # cbrt
    cell = pt.minimum(1.0, np.pi * a_i**2 / lam**2)
    a_r = a_ac * pt.where(flat, 1.0, frac + one_minus * cell)
    e0 = 1.0 / (cs / p["E_fingerpad"] + cm)
    mu = (p["tau0"] * a_r / f_safe + p["alpha"]
          + p["beta_h"] * (9.0 / (128.0 * c["R_e"])) ** (2.0 / 3.0) * (f_safe / e0) ** (1.0 / 3.0))
    return {"friction_coefficient": mu}, {}, ok


def _contact_area(p, x, c):
    """skinfit.physics.contact_area.contact_area: log-linear power laws of f, coefficients linear in f_a."""
    import pytensor.tensor as pt

    f, fa = x["normal_force"], x["actuation_force"]
    log_f = np.log(np.where(f > 0, f, 1.0))
    m = p["m0"] + p["m1"] * fa
    n = p["n_z0"] + p["n_z1"] * fa
    log_area = pt.log(p["alpha_a0"]) + p["alpha_a1"] * fa + m * log_f
    log_imp = pt.log(p["beta_z0"]) + p["beta_z1"] * fa + n * log_f
    ok = pt.all(m > 0) & pt.all(n > 0) & np.array(bool((f > 0).all()))
    return ({"contact_area": pt.exp(log_area), "impedance": pt.exp(log_imp)},
            {"contact_area": log_area, "impedance": log_imp}, ok)


def _wavy_surface(p, x, c):
    """skinfit.physics.wavy.wavy_surface: two-point model, friction mu*f**n per point."""
    import pytensor.tensor as pt

    pos, amp, lam, d, fy = (x[k] for k in ("position", "amplitude", "wavelength", "direction", "normal_force"))
    kk = 2.0 * np.pi / lam
    sin_al = np.sin(np.arctan(-amp * kk * np.sin(kk * pos)))  # covariates only
    shift = p["R"] * sin_al
    weights = []
    for sign in (1.0, -1.0):
        u = 1.0 - ((sign * p["r"] - shift) / p["s"]) ** 2
        inside = u > 0
        weights.append(pt.where(inside, pt.sqrt(pt.where(inside, u, 1.0)), 0.0))
    total = weights[0] + weights[1]
    ok = total > 0.0
    safe_total = pt.where(ok, total, 1.0)
    ratio = 0.0
    for sign, w in zip((1.0, -1.0), weights):
        share = w / safe_total
        loaded = share > 0.0
        load = pt.where(loaded, share * fy, 1.0)
        mu_pm = d * p["mu"] * load ** p["n"]
        g = -amp * kk * pt.sin(kk * (pos + sign * p["r"]))
        denom = 1.0 - mu_pm * g
        ok = ok & ~(loaded & (denom <= 0.0))
        single = (g + mu_pm) / pt.where(denom > 0.0, denom, 1.0)
        ratio = ratio + pt.where(loaded, share * single, 0.0)
    return {"force_ratio": ratio}, {}, pt.all(ok)


def _ultrasonic(p, x, c):
    """skinfit.physics.ultrasonic.ultrasonic with its parameters shared by all rows: mu_E at
    fixed interpolation speeds (Chebyshev points in log speed; they depend only on the
    covariates) times one matrix, the rows' period averages over skinfit's quadrature nodes
    (fused.ultrasonic_interpolation)."""
    import pytensor.tensor as pt

    inv_v, v2, matrix = ultrasonic_interpolation(x)
    u = p["V0"] * inv_v
    e = pt.exp(-u)
    small = u < 1e-2  # series there (as skinfit); both sides see a harmless argument
    us = pt.where(small, u, 0.0)
    ul = pt.where(small, 1.0, u)
    bracket = pt.where(small, _bracket_series(us), -pt.expm1(-ul) / ul - e)  # the series: arithmetic alone
    mu_star = p["mu_inf"] + (p["mu_inf"] - p["mu_0"]) * pt.exp(-v2 / p["k_V"])
    mu_e = 2.0 * mu_star * (p["q"] + 1.0) * bracket / (1.0 + p["q"] - e)
    return {"friction_coefficient": pt.dot(matrix, mu_e)}, {}, 2.0 * p["mu_inf"] - p["mu_0"] > 0.0


FORWARDS = {"electroadhesion": _electroadhesion, "textured_surface": _textured_surface,
            "contact_area": _contact_area, "wavy_surface": _wavy_surface, "ultrasonic": _ultrasonic}


# ---- priors ---------------------------------------------------------------------------------
def _prior_rv(slot):
    """The slot's truncated, renormalised prior as a named PyMC variable (natural units)."""
    import pymc as pm
    import pytensor.tensor as pt

    prior, name = slot.prior, slot.name
    a, lo, hi = prior.args, prior.lower, prior.upper
    lower, upper = (_f(lo) if math.isfinite(lo) else None), (_f(hi) if math.isfinite(hi) else None)
    if prior.dist == "uniform":
        return pm.Uniform(name, lower=_f(lo), upper=_f(hi))
    if prior.dist == "loguniform":  # density 1/(x log(hi/lo)) on [lo, hi]: uniform + correction
        rv = pm.Uniform(name, lower=_f(lo), upper=_f(hi))
        pm.Potential(f"{name}__loguniform", -pt.log(rv) - _f(math.log(math.log(hi / lo)) - math.log(hi - lo)))
        return rv
    if prior.dist in ("normal", "halfnormal"):  # halfnormal(s) on [lo, hi] = normal(0, s) on [lo >= 0, hi]
        loc = a["loc"] if prior.dist == "normal" else 0.0
        if lower is None and upper is None:
            return pm.Normal(name, mu=_f(loc), sigma=_f(a["scale"]))
        return pm.TruncatedNormal(name, mu=_f(loc), sigma=_f(a["scale"]), lower=lower, upper=upper)
    cls, support = {"lognormal": (pm.LogNormal, (0.0, math.inf)), "gamma": (pm.Gamma, (0.0, math.inf)),
                    "beta": (pm.Beta, (0.0, 1.0))}[prior.dist]
    kwargs = {"lognormal": lambda: dict(mu=_f(math.log(a["median"])), sigma=_f(a["sigma"])),
              "gamma": lambda: dict(alpha=_f(a["shape"]), beta=_f(1.0 / a["scale"])),
              "beta": lambda: dict(alpha=_f(a["a"]), beta=_f(a["b"]))}[prior.dist]()
    if lo <= support[0] and hi >= support[1]:  # bounds = support: nothing to truncate
        return cls(name, **kwargs)
    return pm.Truncated(name, cls.dist(**kwargs), lower=_f(lo), upper=_f(hi))


# ---- the model ------------------------------------------------------------------------------
def _distinct_rows(post):
    """Distinct data rows (covariates and levels of split parameters, as skinfit's Posterior
    groups them): ``(first, inverse, counts)``, groups in order of first appearance."""
    cols = [np.ascontiguousarray(v, dtype=float).view(np.int64) for v in post.x.values()]
    cols += [np.asarray(j) for j in post._param_index.values() if not isinstance(j, (int, np.integer))]
    _, first, inverse, counts = np.unique(np.column_stack(cols), axis=0, return_index=True, return_inverse=True,
                                          return_counts=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return first[order], rank[inverse.reshape(-1)], counts[order].astype(float)


def build_pymc(post, rows="all"):
    """A ``pymc.Model`` of ``post`` (see the module docstring); build and compile it inside
    :func:`float64_constants` for float64 constants throughout.

    ``rows="all"`` (default): the forward model on every data row and the observations as
    observed variables, as a PyMC user writes it.  ``rows="distinct"``: the forward model on the
    distinct rows only and a normal / log-normal likelihood from each group's count, mean and
    within-group sum of squares, as a ``pm.Potential`` per observable (the same density exactly;
    what skinfit's Posterior does since it groups repeated measurements; Student-t noise stays
    per row).
    """
    import pymc as pm
    import pytensor.tensor as pt

    if post.model.id not in FORWARDS:
        raise KeyError(f"no pytensor forward model for {post.model.id!r} (have: {', '.join(FORWARDS)})")
    if rows not in ("all", "distinct"):
        raise ValueError(f"rows must be 'all' or 'distinct' (got {rows!r})")
    if rows == "distinct":
        first, inverse, counts = _distinct_rows(post)
    else:
        first, inverse, counts = np.arange(post.n), np.arange(post.n), np.ones(post.n)
    x = {c: v[first] for c, v in post.x.items()}
    with pm.Model() as model:
        rvs = [_prior_rv(s) for s in post.slots]
        p = {}
        for pname, idx in post._param_index.items():
            if isinstance(idx, (int, np.integer)):
                p[pname] = rvs[int(idx)]
            else:  # split: the slots of its levels are contiguous, gathered per data row by a
                # one-hot product (exact; pytensor compiles the gradient of an integer-array
                # gather of a stack of scalars very slowly: 13 levels, 1638 rows: 33 s vs 2 s)
                first_slot = int(np.min(idx))
                levels = [j for j, s in enumerate(post.slots) if s.base == pname]
                assert levels == list(range(first_slot, first_slot + len(levels)))
                code = np.asarray(idx)[first] - first_slot
                onehot = (code[:, None] == np.arange(len(levels))).astype(float)
                p[pname] = pt.dot(onehot, pt.stack([rvs[j] for j in levels]))
        pred, logpred, ok = FORWARDS[post.model.id](p, x, post.constants)
        pm.Potential("support", pt.switch(ok, 0.0, -np.inf) if not isinstance(ok, bool)
                     else pt.constant(0.0 if ok else -np.inf))
        for o in post.observables:
            suffix = "" if len(post.observables) == 1 else f"_{o}"
            sigma = p[f"sigma{suffix}"]
            mu = pt.broadcast_to(pred[o], (len(first),))
            lognormal = post.noise[o] == "lognormal"
            if rows == "distinct" and post.noise[o] in ("normal", "lognormal"):
                v = np.log(post.y[o]) if lognormal else post.y[o]
                mean = np.bincount(inverse, v, len(first)) / counts
                ssw = np.bincount(inverse, (v - mean[inverse]) ** 2, len(first))
                d = mean - (logpred.get(o, pt.log(mu)) if lognormal else mu)
                pm.Potential(o, -0.5 * pt.sum((ssw + counts * d**2) / sigma**2)
                             - pt.sum(counts * pt.log(sigma))
                             - _f(0.5 * post.n * math.log(2 * math.pi) + (v.sum() if lognormal else 0.0)))
                continue
            if rows == "distinct":  # Student-t: per row
                mu = mu[inverse]
                sigma = sigma if sigma.ndim == 0 else sigma[inverse]
            if lognormal:
                pm.LogNormal(o, mu=logpred.get(o, pt.log(mu)), sigma=sigma, observed=post.y[o])
            elif post.noise[o] == "student_t":
                nu = p[f"nu{suffix}"]
                nu = nu[inverse] if rows == "distinct" and nu.ndim else nu
                pm.StudentT(o, nu=nu, mu=mu, sigma=sigma, observed=post.y[o])
            else:
                pm.Normal(o, mu=mu, sigma=sigma, observed=post.y[o])
    return model


def _points(post, n, rng):
    """n natural-parameter points: half prior draws with a finite log density, half around the
    MAP (skinfit.inference.optimize.find_map) jittered by 1% in the sampling coordinates."""
    from skinfit.inference.optimize import find_map

    draws = post.sample_prior(200 * n, rng)
    draws = draws[np.isfinite(post.log_density(draws))][: n // 2]
    z_map = post.to_z(find_map(post, rng, n_global=2000, n_local=1).theta[None])
    near = post.to_theta(z_map + 0.01 * rng.standard_normal((4 * n, post.ndim)))
    near = near[np.isfinite(post.log_density(near))][: n - len(draws)]
    return np.concatenate([draws, near])


def check_pymc(post, model=None, n=20, rng=None, theta=None, rows="all"):
    """Assert PyMC's log density (natural parameters, no Jacobian) equals ``post.log_density``
    to 1e-8 relative or 1e-6 absolute at ``theta`` (k, d), by default ``n`` points from
    :func:`_points`, and that its gradient there is finite.  Returns a dict of the differences.

    Evaluated on a copy of ``model`` without value transforms (``remove_value_transforms``), so
    the compiled function takes natural parameters directly.
    """
    from pymc.model.transform.conditioning import remove_value_transforms

    rng = np.random.default_rng(rng)
    with float64_constants():
        model = build_pymc(post, rows) if model is None else model
        theta = _points(post, n, rng) if theta is None else np.atleast_2d(theta)
        natural = remove_value_transforms(model)
        logp = natural.compile_logp(jacobian=False)
        dlogp = natural.compile_dlogp(jacobian=False)
        names = [v.name for v in natural.value_vars]
        assert sorted(names) == sorted(post.names), (names, post.names)
        col = [post.names.index(v) for v in names]
        ours = np.array([float(logp({v: theta[i, j] for v, j in zip(names, col)})) for i in range(len(theta))])
        grads = np.array([dlogp({v: theta[i, j] for v, j in zip(names, col)}) for i in range(len(theta))])
    ref = post.log_density(theta)
    assert np.isfinite(ref).all(), "check points must lie inside the support"
    diff = np.abs(ours - ref)
    ok = (diff <= 1e-8 * np.abs(ref)) | (diff <= 1e-6)
    assert ok.all(), f"{post.model.id}: PyMC logp differs by up to {diff.max():.3g} (at {int((~ok).sum())} points)"
    bad = int((~np.isfinite(grads)).any(axis=1).sum())
    assert bad == 0, f"{post.model.id}: non-finite PyMC gradient at {bad} of {len(theta)} points"
    return {"n": len(theta), "max_abs": float(diff.max()), "max_rel": float((diff / np.abs(ref)).max()),
            "logp_range": (float(ref.min()), float(ref.max())), "grad_finite": True}


def _compile_cache_files():
    """Files in pytensor's compile cache (C and numba): it grows when a run compiles afresh
    (the first run of a model in an environment took 1.2-2.9x as long as later ones: bench/README.md)."""
    import pytensor

    return sum(1 for _ in Path(pytensor.config.compiledir).parent.rglob("*"))


def run_pymc(post, seed, draws=1000, tune=1000, chains=2, cores=2, attempts=2, rows="all"):
    """PyMC NUTS on ``post``'s model, likelihood and priors (:func:`build_pymc`).

    PyMC's default start (prior midpoints, jittered) can lie outside the physical support, so
    all chains start, unjittered (``init="adapt_diag"``), from the best of 2000 prior draws
    (timed).  Wall time includes building and compiling the model.  If the first run misses the
    criterion, a second run with proportionally more draws follows; the wall time is the sum.
    ``rows``: see :func:`build_pymc` (default ``"all"``, as bench_electroadhesion.py always had it).
    """
    import pymc as pm

    wall, evals, divergences, ess, rhat, runs = 0.0, 0, 0, 0.0, np.inf, []
    cached = _compile_cache_files()
    with PeakRSS() as mem:
        for attempt in range(attempts):
            t0 = time.perf_counter()
            prior_draws = post.sample_prior(2000, np.random.default_rng(seed + attempt))
            start = dict(zip(post.names, prior_draws[np.argmax(post.log_density(prior_draws))]))
            with float64_constants(), build_pymc(post, rows):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    tree = pm.sample(draws=draws, tune=tune, chains=chains, cores=cores, random_seed=seed + attempt,
                                     initvals=start, init="adapt_diag", progressbar=False,
                                     compute_convergence_checks=False)
            wall += time.perf_counter() - t0
            posterior = tree["posterior"].to_dataset()
            stats = tree["sample_stats"].to_dataset()
            ess, rhat = diagnostics(np.stack([posterior[n].values for n in post.names], axis=-1))
            evals += int(stats["n_steps"].values.sum())
            div = int(stats["diverging"].values.sum())
            divergences += div
            runs.append(f"{draws} draws: ESS {ess:.0f}, R-hat {rhat:.3f}, {div} divergences")
            if ess >= 400 and rhat <= 1.01:
                break
            draws = int(min(4000, math.ceil(1.5 * draws * 400 / max(ess, 20))))
    grown = _compile_cache_files() - cached
    note = (f"chains={chains} cores={cores}, tune={tune}, rows={rows}; runs: {'; '.join(runs)}; "
            f"{divergences} divergences; compile cache {'cold (' + str(grown) + ' files added)' if grown else 'warm'}; "
            "evaluations = leapfrog steps (gradient+log-density) of kept draws; RSS growth excludes worker processes")
    return Result("PyMC NUTS", wall, ess, rhat, evals, mem.mb, note,
                  extra={"divergences": divergences, "runs": runs, "tree": tree})
