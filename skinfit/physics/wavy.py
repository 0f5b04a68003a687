"""Fingertip sliding over a sinusoidal surface (Fujii, Okamoto & Yamada; docs/models/wavy_surface.md).

The force ratio f_x/f_y of a finger sliding over ``y(x) = a*cos(2*pi*x/lambda)``: the ball-
bearing model (ratio = surface slope, eq. 2) and the two-point model, in which the contact is
represented by two balls at ``x - r`` and ``x + r`` loaded by a Hertz-like pressure profile whose
centre shifts uphill by ``R*sin(alpha)`` (eqs. 6-8), each sliding with a load-dependent
friction coefficient ``mu*f**n`` (eqs. 9-13).
"""

import numpy as np

__all__ = ["slope", "ball_bearing_ratio", "two_point_ratio", "wavy_surface", "wavy_ball_bearing",
           "wavy_two_point_coulomb"]


def slope(x, amplitude, wavelength):
    """Surface gradient dy/dx of ``y = a*cos(2*pi*x/lambda)`` [-]; lengths in metres."""
    k = 2.0 * np.pi / wavelength
    return -amplitude * k * np.sin(k * x)


def ball_bearing_ratio(x, amplitude, wavelength):
    """Force ratio of a frictionless point contact: the surface slope (eq. 2 of Fujii, Okamoto & Yamada)."""
    return slope(x, amplitude, wavelength)


def two_point_ratio(x, amplitude, wavelength, direction, normal_force, R, r, s, mu, n):
    """Force ratio of the two-point model with friction ``mu*f**n`` per point (eqs. 6-13).

    All arguments broadcast (parameters as (k, 1) against rows (n,)). Returns
    ``(ratio, ok)``: ``ok`` is False where no point is loaded (``s`` too small for the
    slope) or the friction cone locks at a loaded point (``1 - mu_pm*g(x +- r) <= 0``).
    Unloaded points contribute nothing (no 0*inf). A scalar ``n == 0`` (load-independent
    friction) skips the power.
    """
    g0 = slope(x, amplitude, wavelength)
    # centre of pressure moves uphill by R*sin(alpha), alpha = arctan(g0) (eq. 6), in units of s
    shift = (R / s) * (g0 / np.sqrt(1.0 + g0 * g0))
    half = r / s
    weights = []
    for sign in (1.0, -1.0):  # Hertz-like pressure at x +- r (eq. 7): sqrt(1 - ((+-r - shift)/s)^2)
        u = sign * half - shift
        weights.append(np.sqrt(np.maximum(1.0 - u * u, 0.0)))
    total = weights[0] + weights[1]
    ok = total > 0.0
    inv_total = 1.0 / np.where(ok, total, 1.0)
    coulomb = np.ndim(n) == 0 and n == 0
    mu_dir = direction * mu
    ratio = 0.0
    for sign, w in zip((1.0, -1.0), weights):
        share = w * inv_total                        # f_pm / f_y (eq. 8)
        loaded = share > 0.0
        # eq. 12, signed by the sliding direction; an unloaded point's load is set to 1 (no 0**n)
        mu_pm = mu_dir if coulomb else mu_dir * np.where(loaded, share * normal_force, 1.0) ** n
        g = slope(x + sign * r, amplitude, wavelength)
        denom = 1.0 - mu_pm * g
        locked = denom <= 0.0
        ok = ok & ~(loaded & locked)
        single = (g + mu_pm) / np.where(locked, 1.0, denom)  # one ball's ratio (eqs. 9, 11)
        ratio = ratio + np.where(loaded, share * single, 0.0)
    return ratio, ok


def _covariates(x):
    return x["position"], x["amplitude"], x["wavelength"], x["direction"], x["normal_force"]


def wavy_surface(p, x, c):
    """Two-point model with load-dependent friction (eqs. 6-13 of Fujii, Okamoto & Yamada).

    Parameters ``R``, ``r``, ``s`` [m], ``mu`` [-] (at 1 N per point), ``n`` [-]; covariates
    ``position``, ``amplitude``, ``wavelength`` [m], ``direction`` (+1/-1), ``normal_force`` [N].
    """
    pos, a, lam, d, fy = _covariates(x)
    ratio, ok = two_point_ratio(pos, a, lam, d, fy, p["R"], p["r"], p["s"], p["mu"], p["n"])
    return {"force_ratio": ratio}, ok


def wavy_two_point_coulomb(p, x, c):
    """The two-point model with a load-independent friction coefficient (``n = 0``)."""
    pos, a, lam, d, fy = _covariates(x)
    ratio, ok = two_point_ratio(pos, a, lam, d, fy, p["R"], p["r"], p["s"], p["mu"], 0.0)
    return {"force_ratio": ratio}, ok


def wavy_ball_bearing(p, x, c):
    """Ball-bearing model: the force ratio is the surface slope (eq. 2); only noise parameters."""
    pos, a, lam, _, _ = _covariates(x)
    ratio = ball_bearing_ratio(pos, a, lam)
    k = max((len(np.atleast_1d(v)) for v in p.values()), default=1)
    return {"force_ratio": np.broadcast_to(ratio, (k, np.size(ratio)))}, np.True_
