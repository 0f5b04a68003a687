"""Hand-fused numpy log-posteriors: the throughput floor of skinfit's ``Posterior.__call__``.

``make_fused(post)`` returns ``fused(z)``, which computes exactly ``post(z)`` (the log posterior
in skinfit's sampling coordinates, Jacobian included, -inf outside the prior bounds or the
model's physical support) for the five benchmark model families, as one hand-written numpy
expression per family: covariates, constants, prior arguments and row orders are prepared once,
the hot path has no Python loop over walkers and no dict look-up.  The same forward model, the
same noise model and the same truncated, renormalised priors as skinfit; only the arithmetic is
arranged by hand (e.g. ``log theta`` read from ``z`` where the coordinate is a plain log), and,
like skinfit's Posterior, the forward model runs once per distinct data row (repeated
measurements), the normal / log-normal likelihood coming from each group's count, mean and
within-group sum of squares (an exact identity; :func:`_distinct`).

Each builder asserts the slot names and sampling transforms it was written for, so a change of
skinfit's coordinates fails loudly.  ``check_fused`` compares against ``post(z)``.
"""

import math

import numpy as np

from skinfit.physics.ultrasonic import PHASES, _bracket_series, _interpolation, _rows

__all__ = ["make_fused", "check_fused", "FAMILIES", "ultrasonic_interpolation"]

_LOG_2PI = math.log(2.0 * math.pi)


def _expect(post, names, transforms, noise):
    """Fail loudly if skinfit's coordinates or noise model are not the ones the code was written for."""
    got = (post.names, [s.transform for s in post.slots], dict(post.noise))
    want = (tuple(names), list(transforms), dict(noise))
    assert got == want, (f"fused {post.model.id}: written for slots {want[0]}, transforms {want[1]}, noise "
                         f"{want[2]}; this posterior has {got[0]}, {got[1]}, {got[2]}")


def _prior(post):
    """``(lp, lo, hi)``: the normalised log prior without its bounds check, as a closure over
    per-family column groups (the closed forms of skinfit.io.priors.LOG_DENSITIES), and the bounds."""
    sq, ln, lg, lin, l1p = [], [], [], [], []  # (column, arguments)
    for j, s in enumerate(post.slots):
        a = s.prior.args
        if s.prior.dist == "normal":
            sq.append((j, a["loc"], a["scale"]))
        elif s.prior.dist == "halfnormal":
            sq.append((j, 0.0, a["scale"]))
        elif s.prior.dist == "lognormal":
            ln.append((j, math.log(a["median"]), a["sigma"]))
        elif s.prior.dist == "loguniform":
            lg.append((j, -1.0))
        elif s.prior.dist == "gamma":
            lg.append((j, a["shape"] - 1.0))
            lin.append((j, -1.0 / a["scale"]))
        elif s.prior.dist == "beta":
            lg.append((j, a["a"] - 1.0))
            l1p.append((j, a["b"] - 1.0))
        else:
            assert s.prior.dist == "uniform", s.prior.dist

    def cols(group):
        return tuple(np.array(v) for v in zip(*group)) if group else None

    sq, ln, lg, lin, l1p = map(cols, (sq, ln, lg, lin, l1p))
    const = -float(post._log_norm)

    def lp(theta):
        total = np.full(len(theta), const)
        if sq is not None:
            r = (theta[:, sq[0]] - sq[1]) / sq[2]
            total = total - 0.5 * (r * r).sum(axis=1)
        if ln is not None:
            lx = np.log(theta[:, ln[0]])
            r = (lx - ln[1]) / ln[2]
            total = total - lx.sum(axis=1) - 0.5 * (r * r).sum(axis=1)
        if lg is not None:
            total = total + np.log(theta[:, lg[0]]) @ lg[1]
        if lin is not None:
            total = total + theta[:, lin[0]] @ lin[1]
        if l1p is not None:
            total = total + np.log1p(-theta[:, l1p[0]]) @ l1p[1]
        return total

    return lp, post._lo.copy(), post._hi.copy()


def _distinct(post):
    """Repeated measurements, grouped once: ``(x_u, counts, stats)`` where ``x_u`` holds the
    covariates of the distinct rows (order of first appearance), ``counts`` (float) how often each
    occurs, and ``stats[obs] = (mean, within-group sum of squares over all groups)`` of the
    observable (of its log for log-normal noise), so that
    ``sum_i (y_i - mu_row(i))**2 = ssw + sum_u counts_u * (mean_u - mu_u)**2`` exactly.
    (skinfit's Posterior groups its rows the same way; this is computed independently.)"""
    keys = np.column_stack([np.ascontiguousarray(v, dtype=float).view(np.int64) for v in post.x.values()])
    _, first, inverse, counts = np.unique(keys, axis=0, return_index=True, return_inverse=True, return_counts=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    first, inverse, counts = first[order], rank[inverse.reshape(-1)], counts[order].astype(float)
    stats = {}
    for o in post.observables:
        v = np.log(post.y[o]) if post.noise[o] == "lognormal" else post.y[o]
        mean = np.bincount(inverse, v, len(first)) / counts
        stats[o] = (mean, float(((v - mean[inverse]) ** 2).sum()))
    return {c: v[first] for c, v in post.x.items()}, counts, stats


# ---- electroadhesion -----------------------------------------------------------------------
def _electroadhesion(post):
    """The card's sampling coordinates (d_air shifted log, beta0 product, phi sheared), forward
    model on the distinct rows, normal likelihood, prior and Jacobian written out by hand."""
    from skinfit.physics.electroadhesion import air_gap_shift, phi_offset

    _expect(post, ("E_star", "tau0", "d_air", "beta0", "phi", "eta", "alpha", "sigma"),
            ["log", "log", "shift_log", "product", "log", "log", "log", "log"], {"tangential_force": "normal"})
    (j, partners, powers), = post._product
    assert j == 3 and list(partners) == [1, 0] and np.allclose(powers, [1.0, -2.0 / 3.0])
    assert [(j, f) for j, f in post._shear] == [(4, phi_offset)]
    c = post.constants
    xu, cnt, stats = _distinct(post)
    fn, v2 = xu["normal_force"], xu["voltage"] ** 2
    ybar, ssw = stats["tangential_force"]
    n = post.n
    prior, lo, hi = _prior(post)
    const = -0.5 * n * _LOG_2PI
    t_fixed = c["d_sio2"] / c["eps_sio2"] + c["d_sc"] / c["eps_sc"]
    shift = c["eps_air"] * t_fixed
    assert np.isclose(shift, air_gap_shift(c), rtol=1e-14) and np.isclose(post._shift[0], shift, rtol=1e-14)
    log_shift = math.log(shift)
    eps_air, half_eps0, three_pi_r, jkr = c["eps_air"], 0.5 * c["eps0"], 3.0 * math.pi * c["R"], 3.0 * c["R"] / 4.0

    def fused(z):
        theta = np.exp(z)
        e_star, tau0, _, x_prod, phi_s, eta, alpha, sigma = theta.T[:, :, None]
        d_air = shift * np.expm1(z[:, 2:3] - log_shift)
        beta0 = z[:, 3:4] * e_star ** (2.0 / 3.0) / tau0
        t = t_fixed + d_air / eps_air
        phi = phi_s * t
        dg = half_eps0 * v2 / t
        k = three_pi_r * dg
        a0 = math.pi * np.cbrt(jkr / e_star * (fn + k + np.sqrt(2.0 * k * fn + k * k))) ** 2
        b = tau0 * (beta0 + phi * dg)
        cc = b * a0 + alpha * fn
        disc = 1.0 + 4.0 * b * eta * cc
        ft = 2.0 * cc / (1.0 + np.sqrt(np.abs(disc)))
        d = ybar - ft
        theta[:, 2], theta[:, 3], theta[:, 4] = d_air[:, 0], beta0[:, 0], phi[:, 0]
        ok = ((disc >= 0) & (a0 - eta * ft * ft > 0)).all(axis=1) & ((theta >= lo) & (theta <= hi)).all(axis=1)
        log_jac = z.sum(axis=1) - z[:, 3] - z[:, 1] + (2.0 / 3.0) * z[:, 0] + np.log(t[:, 0])
        ss = (ssw + (cnt * d * d).sum(axis=1)) / (sigma[:, 0] * sigma[:, 0])
        return np.where(ok, prior(theta) + const - 0.5 * ss - n * z[:, 7] + log_jac, -np.inf)

    return fused


# ---- textured_surface ----------------------------------------------------------------------
def _textured_surface(post):
    """Distinct rows, textured first, flat references after (their real area is the apparent area)."""
    _expect(post, ("E_skin_micro", "E_fingerpad", "tau0", "alpha", "beta_h", "k_a", "m_a", "sigma"),
            ["log", "log", "log", "identity", "product", "log", "log", "log"], {"friction_coefficient": "normal"})
    (j, partners, powers), = post._product
    assert j == 4 and list(partners) == [1] and np.allclose(powers, [-1.0 / 3.0])
    c = post.constants
    xu, cnt, stats = _distinct(post)
    ybar, ssw = stats["friction_coefficient"]
    geo = [xu[k] for k in ("asperity_radius", "asperity_height", "asperity_spacing")]
    missing = [np.isnan(g) for g in geo]
    flat = missing[0] & missing[1] & missing[2]
    valid = bool(((missing[0] == missing[1]) & (missing[1] == missing[2]) & (xu["normal_force"] > 0)).all())
    order = np.concatenate([np.flatnonzero(~flat), np.flatnonzero(flat)])
    nt = int((~flat).sum())
    f, em, ybar, cnt = xu["normal_force"][order], xu["sample_modulus"][order], ybar[order], cnt[order]
    r_asp, h, lam = (g[order][:nt] for g in geo)
    logf = np.log(np.where(f > 0, f, 1.0))
    cs, cm = 1.0 - c["nu_skin"] ** 2, (1.0 - c["nu_m"] ** 2) / em  # 1/E = cs/E_skin + cm
    lam2 = lam ** 2
    crit = (2.0 / 3.0) * (4.0 / 3.0) * np.sqrt(r_asp) * h ** 1.5 / lam2  # 2*F_crit/(3*F_i) = crit*e1/pbar
    hertz = 3.0 * lam2 * r_asp / 4.0
    hyst = (9.0 / (128.0 * c["R_e"])) ** (2.0 / 3.0)
    prior, lo, hi = _prior(post)
    n = post.n
    const = -0.5 * n * _LOG_2PI

    def fused(z):
        theta = np.exp(z)
        theta[:, 3] = z[:, 3]  # alpha in natural units
        theta[:, 4] = z[:, 4] * np.cbrt(theta[:, 1])  # z = beta_h * E_fingerpad^(-1/3)
        e_micro, e_pad, tau0, alpha, beta_h, k_a, m_a, sigma = theta.T[:, :, None]
        e1 = 1.0 / (cs / e_micro + cm[:nt])
        a_ac = k_a * np.exp(m_a * logf)
        pbar = f / a_ac
        pt_ = pbar[:, :nt]
        s = crit * e1 / pt_
        frac = np.clip(1.0 - s * s, 0.0, 1.0)
        one_minus = 1.0 - frac
        a_i = np.cbrt(hertz * pt_ * np.sqrt(one_minus) / e1)
        area = np.ones_like(pbar)
        area[:, :nt] = frac + one_minus * np.minimum(1.0, math.pi * a_i * a_i / lam2)
        mu = tau0 * a_ac * area / f + alpha + beta_h * hyst * np.cbrt(f * (cs / e_pad + cm))
        d = ybar - mu
        ss = (ssw + (cnt * d * d).sum(axis=1)) / (sigma[:, 0] * sigma[:, 0])
        ok = ((theta >= lo) & (theta <= hi)).all(axis=1) & valid
        log_jac = z.sum(axis=1) - z[:, 3] - z[:, 4] + z[:, 1] / 3.0
        return np.where(ok, prior(theta) + const - 0.5 * ss - n * z[:, 7] + log_jac, -np.inf)

    return fused


# ---- contact_area --------------------------------------------------------------------------
def _contact_area(post):
    """Two log-normal observables; log-predictions linear in the parameters (eqs. 3-4 of Huloux, Willemet & Wiertlewski)."""
    _expect(post, ("alpha_a0", "alpha_a1", "m0", "m1", "beta_z0", "beta_z1", "n_z0", "n_z1",
                   "sigma_contact_area", "sigma_impedance"),
            ["log", "identity", "log", "identity", "log", "identity", "log", "identity", "log", "log"],
            {"contact_area": "lognormal", "impedance": "lognormal"})
    xu, cnt, stats = _distinct(post)
    f, fa = xu["normal_force"], xu["actuation_force"]
    valid = bool((f > 0).all())
    logf = np.log(np.where(f > 0, f, 1.0))
    (abar, assw), (zbar, zssw) = stats["contact_area"], stats["impedance"]
    n = post.n
    const = -n * _LOG_2PI - np.log(post.y["contact_area"]).sum() - np.log(post.y["impedance"]).sum()
    expo = np.array([s.transform == "log" for s in post.slots])
    prior, lo, hi = _prior(post)

    def fused(z):
        theta = z.copy()
        theta[:, expo] = np.exp(z[:, expo])
        a0, a1, m0, m1, b0, b1, n0, n1, s_a, s_z = theta.T[:, :, None]
        m = m0 + m1 * fa
        nz = n0 + n1 * fa
        da = abar - (z[:, 0:1] + a1 * fa + m * logf)
        dz = zbar - (z[:, 4:5] + b1 * fa + nz * logf)
        ss = ((assw + (cnt * da * da).sum(axis=1)) / (s_a[:, 0] * s_a[:, 0])
              + (zssw + (cnt * dz * dz).sum(axis=1)) / (s_z[:, 0] * s_z[:, 0]))
        ok = (m > 0).all(axis=1) & (nz > 0).all(axis=1) & ((theta >= lo) & (theta <= hi)).all(axis=1) & valid
        return np.where(ok, prior(theta) + const - 0.5 * ss - n * (z[:, 8] + z[:, 9]) + z[:, expo].sum(axis=1),
                        -np.inf)

    return fused


# ---- wavy_surface --------------------------------------------------------------------------
def _wavy_surface(post):
    """Two-point model with load-dependent friction, both points in one expression."""
    _expect(post, ("R", "r", "s", "mu", "n", "sigma"), ["log", "log", "log", "log", "identity", "log"],
            {"force_ratio": "normal"})
    xu, cnt, stats = _distinct(post)
    ybar, ssw = stats["force_ratio"]
    pos, amp, lam, d, fy = (xu[k] for k in ("position", "amplitude", "wavelength", "direction", "normal_force"))
    kk = 2.0 * np.pi / lam
    ak = -amp * kk
    sin_al = np.sin(np.arctan(ak * np.sin(kk * pos)))  # centre-of-pressure shift / R
    n_rows = post.n
    const = -0.5 * n_rows * _LOG_2PI
    expo = np.array([s.transform == "log" for s in post.slots])
    prior, lo, hi = _prior(post)

    def fused(z):
        theta = np.exp(z)
        theta[:, 4] = z[:, 4]
        big_r, r, s, mu, n, sigma = theta.T[:, :, None]
        shift = big_r * sin_al
        inv_s = 1.0 / s
        up, um = (r - shift) * inv_s, (-r - shift) * inv_s
        wp, wm = np.sqrt(np.maximum(1.0 - up * up, 0.0)), np.sqrt(np.maximum(1.0 - um * um, 0.0))
        total = wp + wm
        ok = total > 0.0
        total = np.where(ok, total, 1.0)
        sp, sm = wp / total, wm / total  # load shares; an unloaded point has share 0 and adds 0
        lp_, lm_ = sp > 0.0, sm > 0.0
        dmu = d * mu
        mup = dmu * np.exp(n * np.log(np.where(lp_, sp * fy, 1.0)))  # mu*(share*f_y)**n, signed
        mum = dmu * np.exp(n * np.log(np.where(lm_, sm * fy, 1.0)))
        gp, gm = ak * np.sin(kk * (pos + r)), ak * np.sin(kk * (pos - r))
        dp, dm = 1.0 - mup * gp, 1.0 - mum * gm
        bad = (lp_ & (dp <= 0.0)) | (lm_ & (dm <= 0.0)) | ~ok
        ratio = sp * ((gp + mup) / np.where(dp > 0.0, dp, 1.0)) + sm * ((gm + mum) / np.where(dm > 0.0, dm, 1.0))
        res = ybar - ratio
        ss = (ssw + (cnt * res * res).sum(axis=1)) / (sigma[:, 0] * sigma[:, 0])
        ok = ~bad.any(axis=1) & ((theta >= lo) & (theta <= hi)).all(axis=1)
        return np.where(ok, prior(theta) + const - 0.5 * ss - n_rows * z[:, 5] + z[:, expo].sum(axis=1), -np.inf)

    return fused


# ---- ultrasonic ----------------------------------------------------------------------------
def ultrasonic_interpolation(x):
    """skinfit's period averages with parameters shared by all rows, for covariates ``x``:
    ``(1/c, c^2, matrix)``, mu_E at the interpolation speeds ``c`` times ``matrix.T`` gives every
    row's average (skinfit.physics.ultrasonic._interpolation, computed once from the covariates,
    outside the hot path; its accuracy against the reference quadrature is
    tests/test_physics_ultrasonic.py's)."""
    return _interpolation(*_rows(x), scalars=(PHASES, False))


def _ultrasonic(post):
    """Period average of the distinct rows: mu_E at fixed interpolation speeds (they depend only
    on the covariates) times one matrix (:func:`ultrasonic_interpolation`); mu_inf sampled as
    log(mu_inf / (1 + q)) (the card's shear)."""
    from skinfit.physics.ultrasonic import mu_inf_offset

    _expect(post, ("mu_inf", "mu_0", "k_V", "q", "V0", "sigma"), ["log", "identity", "log", "log", "log", "log"],
            {"friction_coefficient": "normal"})
    assert [(j, f) for j, f in post._shear] == [(0, mu_inf_offset)]
    xu, cnt, stats = _distinct(post)
    ybar, ssw = stats["friction_coefficient"]
    inv, v2, matrix = ultrasonic_interpolation(xu)
    matrix_t = np.ascontiguousarray(matrix.T)
    n = post.n
    const = -0.5 * n * _LOG_2PI
    prior, lo, hi = _prior(post)

    def fused(z):
        theta = np.exp(z)
        theta[:, 1] = z[:, 1]  # mu_0 in natural units
        log1p_q = np.log1p(theta[:, 3])
        theta[:, 0] *= 1.0 + theta[:, 3]
        mu_inf, mu_0, k_v, q, v0, sigma = theta.T[:, :, None]
        u = v0 * inv
        e = np.exp(-u)
        br = -np.expm1(-u) / u - e
        small = u < 1e-2
        if small.any():
            br[small] = _bracket_series(u[small])
        mu_e = 2.0 * (mu_inf + (mu_inf - mu_0) * np.exp(-v2 / k_v)) * (q + 1.0) * br / (1.0 + q - e)
        d = ybar - mu_e @ matrix_t
        ss = (ssw + (cnt * d * d).sum(axis=1)) / (sigma[:, 0] * sigma[:, 0])
        ok = (2.0 * mu_inf[:, 0] - mu_0[:, 0] > 0.0) & ((theta >= lo) & (theta <= hi)).all(axis=1)
        return np.where(ok, prior(theta) + const - 0.5 * ss - n * z[:, 5] + z.sum(axis=1) - z[:, 1] + log1p_q,
                        -np.inf)

    return fused


FAMILIES = {"electroadhesion": _electroadhesion, "textured_surface": _textured_surface,
            "contact_area": _contact_area, "wavy_surface": _wavy_surface, "ultrasonic": _ultrasonic}


def make_fused(post):
    """``fused(z)`` = ``post(z)`` for (k, d) sampling coordinates, one fused numpy expression
    for ``post.model.id`` (KeyError for a model without one; AssertionError if skinfit's slots,
    sampling transforms or noise model differ from those the expression was written for)."""
    if post.model.id not in FAMILIES:
        raise KeyError(f"no fused log-posterior for model {post.model.id!r} (have: {', '.join(FAMILIES)})")
    return FAMILIES[post.model.id](post)


def check_fused(post, fused, z):
    """Assert ``fused(z)`` equals ``post(z)``: same -inf pattern, finite entries within rtol 1e-10.

    Returns ``{"n", "finite", "max_abs", "max_rel"}`` over the finite entries.
    """
    z = np.atleast_2d(np.asarray(z, dtype=float))
    with np.errstate(all="ignore"):
        a, b = fused(z), post(z)
    assert a.shape == b.shape == (len(z),), (a.shape, b.shape)
    assert not np.isnan(a).any(), f"fused gave NaN at {int(np.isnan(a).sum())} points"
    same = np.isneginf(a) == np.isneginf(b)
    assert same.all(), f"-inf pattern differs at {int((~same).sum())} of {len(z)} points"
    fin = np.isfinite(b)
    assert np.isfinite(a[fin]).all()
    assert np.allclose(a[fin], b[fin], rtol=1e-10), f"max |diff| {np.max(np.abs(a[fin] - b[fin])):.3g}"
    diff = np.abs(a[fin] - b[fin])
    return {"n": len(z), "finite": int(fin.sum()), "max_abs": float(diff.max(initial=0.0)),
            "max_rel": float((diff / np.maximum(np.abs(b[fin]), 1e-300)).max(initial=0.0))}
