"""Finger friction vs sliding velocity under longitudinal ultrasonic vibration (seed 004;
MODELS.md section 5).

The equilibrium friction coefficient of stress-aided depinning of polymer chains (eq. 3,
after the molecular friction theories of Schallamach and of Chernyak & Leonov, refs. [19], [14]
of seed 004), with a speed-dependent friction factor (eq. 4), averaged over one vibration
period of the relative velocity between finger and plate (eq. 5).

The period average is a fixed-phase quadrature over [0, pi] (by the symmetry
``cos(wt) = cos(-wt)``), split where the relative velocity's x component changes sign (for
motion along the vibration axis the speed |v_x| has a kink there), with Gauss-Legendre nodes on
each smooth piece. MODELS.md suggests the midpoint rule; measured on the shipped design at the
paper's parameters, the midpoint rule over the half period changed by 6e-3 from 48 to 96 phases
and still by 2e-5 from 1000 to 2000 (O(h^2) at the kink), while ``PHASES`` = 48 Gauss-Legendre
nodes per piece change the average by < 1e-8 when doubled (32 would give 4e-7; the test asks
< 1e-6: tests/test_physics_ultrasonic.py). Off the shipped angles it is slowest near 0.01 rad,
where v_x has a sharp minimum of width ~ v_y (1.3e-6 on doubling; 2e-7 at 0.05 rad). Memory:
the integrand is evaluated on (k, rows, 2*PHASES) arrays, about six at the peak.
"""

from functools import lru_cache

import numpy as np

__all__ = ["PHASES", "mu_equilibrium", "mu_speed", "period_average", "ultrasonic", "ultrasonic_projected",
           "ultrasonic_constant_mu"]

#: Gauss-Legendre nodes per smooth piece of the half period (convergence shown by the tests).
PHASES = 48


#: exp(x) for x < -700 is below 1e-304, negligible beside every term it enters, and numpy's
#: exp takes a slow path (~5x) for arguments whose result underflows: they are clipped here
#: (broad ensembles, e.g. the MAP's prior draws, meet them at many quadrature nodes).
_EXP_FLOOR = -700.0


def _bracket(u, e):
    """``Vs*(1 - exp(-1/Vs)) - exp(-1/Vs)`` with ``u = 1/Vs``, ``e = exp(-u)``; cancellation-free
    for small u (series there)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.asarray((1.0 - e) / u - e)  # 1 - e loses < 1e-14 relative for u >= 1e-2
    small = u < 1e-2
    if small.any():
        s = u[small]  # sum_j (-1)^(j+1) j u^j/(j+1)!, to j = 6
        out[small] = s * (1 / 2 - s * (1 / 3 - s * (1 / 8 - s * (1 / 30 - s * (1 / 144 - s / 840)))))
    return out


def mu_equilibrium(v, mu_star, q, v0):
    """Equilibrium friction coefficient mu_E at speed ``v`` >= 0 [m/s] (eq. 3 of seed 004).

    ``mu_E = 2*mu_star*(q+1)*(Vs*(1-exp(-1/Vs)) - exp(-1/Vs)) / (1 + q - exp(-1/Vs))``,
    ``Vs = v/v0``; tends to 0 as ``v -> 0`` (the bracket behaves like Vs).  ``v`` may lack the
    leading parameter axes of the others (speeds shared by an ensemble): what depends on ``v``
    alone is computed once.
    """
    v = np.asarray(v, dtype=float)
    moving = v > 0.0
    with np.errstate(divide="ignore"):
        inv_v = np.where(moving, 1.0 / np.where(moving, v, 1.0), 1.0)  # no parameter axes yet
    u = np.multiply(v0, inv_v)
    e = np.exp(np.maximum(-u, _EXP_FLOOR))
    value = _bracket(u, e) * mu_star * (2.0 * (np.asarray(q) + 1.0)) / ((1.0 + q) - e)
    return value if moving.all() else np.where(moving, value, 0.0)


def mu_speed(v, mu_inf, mu_0, k_v):
    """Speed-dependent friction factor mu*(V) (eq. 4 of seed 004, sign as printed)."""
    return mu_inf + (mu_inf - mu_0) * np.exp(np.maximum(-(v**2) / k_v, _EXP_FLOOR))


@lru_cache(maxsize=8)
def _gauss_legendre(m):
    """``m`` Gauss-Legendre nodes and weights on [0, 1] (weights summing to 1)."""
    t, w = np.polynomial.legendre.leggauss(m)
    return (t + 1) / 2, w / 2


def _phase_nodes(vf_x, vy, amp_v, m):
    """Phases (..., 2m) on [0, pi] and weights for the average over a period.

    Where ``v_x`` changes sign the speed has a kink (motion along the vibration axis) or a sharp
    minimum of width ~ v_y/(omega*A/2): [0, pi] is split there, and each piece gets ``m``
    Gauss-Legendre nodes (rows where v_x keeps its sign: one piece, the other of zero width).
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(amp_v > 0, vf_x / np.where(amp_v > 0, amp_v, 1.0), -2.0)
    split = np.arccos(np.clip(ratio, -1.0, 1.0))[..., None]  # pi when there is no kink
    t, w = _gauss_legendre(m)
    phases = np.concatenate([split * t, split + (np.pi - split) * t], axis=-1)
    weights = np.concatenate([split * w, (np.pi - split) * w], axis=-1) / np.pi
    return phases, weights


def period_average(f, velocity, angle, amplitude_pp, frequency, m=PHASES):
    """Average over one vibration period of ``f(speed, v_x, v_y)`` (eq. 5 of seed 004).

    The plate vibrates along x with peak-to-peak ``amplitude_pp`` [m] at ``frequency`` [Hz];
    the finger moves at ``velocity`` [m/s] at ``angle`` [rad] to the vibration axis. ``f`` is
    evaluated on arrays with a trailing phase axis and may prepend axes (parameter ensembles).
    Rows without vibration need no average and get a single node.
    """
    velocity, angle, amplitude_pp, frequency = np.broadcast_arrays(velocity, angle, amplitude_pp, frequency)
    vf_x = velocity * np.cos(angle)
    vy = velocity * np.sin(angle)
    amp_v = np.pi * frequency * amplitude_pp  # omega * A/2
    still = amp_v == 0
    parts = {}
    for rows, nodes in ((still, 0), (~still, m)):
        if not rows.any():
            continue
        if nodes:
            phases, weights = _phase_nodes(vf_x[rows], vy[rows], amp_v[rows], nodes)
            vx = vf_x[rows][:, None] - amp_v[rows][:, None] * np.cos(phases)
        else:
            weights = np.ones((int(rows.sum()), 1))
            vx = vf_x[rows][:, None]
        vyy = np.broadcast_to(vy[rows][:, None], vx.shape)
        values = f(np.hypot(vx, vyy), vx, vyy, rows)
        parts[nodes] = (rows, np.einsum("...rn,rn->...r", values, np.broadcast_to(weights, values.shape[-2:])))
    lead = np.broadcast_shapes(*(v.shape[:-1] for _, v in parts.values()))
    out = np.empty(lead + velocity.shape)
    for rows, values in parts.values():
        out[..., rows] = values
    return out


def _rows(x):
    return x["velocity"], x["direction_angle"], x["amplitude_pp"], x["frequency"]


def _average(mu_of_speed, x, projected=False):
    """Period average of the friction coefficient for parameters (k, 1) against rows (n,)."""
    v, angle, amp, freq = _rows(x)
    ux, uy = np.cos(angle)[..., None], np.sin(angle)[..., None]

    def integrand(speed, vx, vy, rows):
        mu = mu_of_speed(speed[None])  # (k, rows, phases)
        if not projected:
            return mu
        with np.errstate(invalid="ignore", divide="ignore"):
            along = np.where(speed > 0, (vx * ux[rows] + vy * uy[rows]) / np.where(speed > 0, speed, 1.0), 0.0)
        return mu * along[None]

    return period_average(integrand, v, angle, amp, freq)


def _support(p):
    """mu*(V) of eq. 4 lies between mu_inf and 2*mu_inf - mu_0: positive iff mu_0 < 2*mu_inf."""
    return 2.0 * p["mu_inf"] - p["mu_0"] > 0.0


def ultrasonic(p, x, c):
    """Friction coefficient: period average of mu_E(|v_r|) with mu* = mu*(|v_r|) (eqs. 3-5).

    Parameters ``mu_inf``, ``mu_0`` [-], ``k_V`` [m^2/s^2], ``q`` [-], ``V0`` [m/s]; covariates
    ``velocity`` [m/s], ``direction_angle`` [rad], ``amplitude_pp`` [m], ``frequency`` [Hz].
    """
    def mu(speed):
        return mu_equilibrium(speed, mu_speed(speed, p["mu_inf"][..., None], p["mu_0"][..., None], p["k_V"][..., None]),
                              p["q"][..., None], p["V0"][..., None])

    return {"friction_coefficient": _average(mu, x)}, _support(p)


def ultrasonic_projected(p, x, c):
    """As :func:`ultrasonic`, averaging only the friction component along the finger's own
    direction, ``mu_E(|v_r|) * (v_r . u_f)/|v_r|`` (the competitor of seed 004's Section IV)."""
    def mu(speed):
        return mu_equilibrium(speed, mu_speed(speed, p["mu_inf"][..., None], p["mu_0"][..., None], p["k_V"][..., None]),
                              p["q"][..., None], p["V0"][..., None])

    return {"friction_coefficient": _average(mu, x, projected=True)}, _support(p)


def ultrasonic_constant_mu(p, x, c):
    """Eq. 1 of seed 004, period-averaged: eq. 3 with the constant ``mu_plus`` in place of mu*(V).

    Read literally: ``mu_plus`` is the prefactor of eq. 1 (the printed brace holds the whole
    fraction), not the peak of mu_E as the paper's prose calls it; at q = 0.0177 the curve
    peaks at 0.905*mu_plus at V = 3.26*V0. At zero amplitude it equals :func:`ultrasonic` at
    any single speed V where ``mu_plus = mu*(V)`` (eq. 4).
    """
    def mu(speed):
        return mu_equilibrium(speed, p["mu_plus"][..., None], p["q"][..., None], p["V0"][..., None])

    return {"friction_coefficient": _average(mu, x)}, np.True_
