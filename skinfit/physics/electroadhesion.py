"""Finger sliding on a touchscreen under electroadhesion (the electroadhesion paper; docs/models/electroadhesion.md).

JKR contact area, adhesive friction with an area ratio that grows with the electroadhesive
energy, and sliding area reduction; plus the two competing variants of the paper.
"""

import numpy as np

__all__ = [
    "phi_offset",
    "air_gap_shift",
    "adhesion_energy",
    "jkr_area",
    "electroadhesion",
    "electroadhesion_coulomb",
    "electroadhesion_empirical",
]


def _series_thickness(d_air, c):
    """Dielectric-weighted stack thickness d_sio2/eps_sio2 + d_air/eps_air + d_sc/eps_sc [m]."""
    return c["d_sio2"] / c["eps_sio2"] + d_air / c["eps_air"] + c["d_sc"] / c["eps_sc"]


def adhesion_energy(voltage, d_air, c):
    """Electroadhesive energy per unit area dgamma [J/m^2], eq. 8 of the electroadhesion paper.

    ``voltage`` [V] and ``d_air`` [m] broadcast against each other.
    """
    return 0.5 * c["eps0"] * voltage**2 / _series_thickness(d_air, c)


def jkr_area(normal_force, dgamma, E_star, R):
    """JKR contact area A0 [m^2] of a sphere of radius ``R`` [m], eq. 6 of the electroadhesion paper.

    Reduces to the Hertz area pi*(3*R*Fn/(4*E_star))**(2/3) when ``dgamma`` is 0.
    """
    k = 3.0 * dgamma * np.pi * R
    radicand = 6.0 * dgamma * np.pi * R * normal_force + k**2
    a3 = (3.0 * R / (4.0 * E_star)) * (normal_force + k + np.sqrt(radicand))
    return np.pi * np.cbrt(a3) ** 2


def electroadhesion(p, x, c):
    """Tangential force [N] of the adhesive-friction model, eqs. 6, 8, 10, 12 of the electroadhesion paper.

    Parameters ``E_star`` [Pa], ``tau0`` [Pa], ``d_air`` [m], ``beta0`` [-], ``phi`` [m^2/J],
    ``eta`` [m^2/N^2], ``alpha`` [-]; covariates ``normal_force`` [N], ``voltage`` [V].

    The implicit ``Ft = B*(A0 - eta*Ft**2) + alpha*Fn`` is solved by its positive root in the
    cancellation-free form ``Ft = 2c / (1 + sqrt(1 + 4*B*eta*c))``, ``c = B*A0 + alpha*Fn``.
    Outside the support: the sliding apparent area ``A0 - eta*Ft**2`` is <= 0.
    """
    fn, v = x["normal_force"], x["voltage"]
    dgamma = adhesion_energy(v, p["d_air"], c)
    a0 = jkr_area(fn, dgamma, p["E_star"], c["R"])
    b = p["tau0"] * (p["beta0"] + p["phi"] * dgamma)
    cc = b * a0 + p["alpha"] * fn
    disc = 1.0 + 4.0 * b * p["eta"] * cc
    ok = disc >= 0.0
    ft = 2.0 * cc / (1.0 + np.sqrt(np.where(ok, disc, 1.0)))
    ok = ok & (a0 - p["eta"] * ft**2 > 0.0)
    return {"tangential_force": ft}, ok


def electroadhesion_coulomb(p, x, c):
    """Coulomb friction with the parallel-plate electrostatic force, eq. 5 of the electroadhesion paper.

    ``Ft = mu*(Fn + Fe)``, ``Fe = eps0*A0*V**2 / (2*eps_air*t**2)`` with the stack thickness
    ``t`` and the JKR area ``A0`` of eq. 6.  Parameters ``mu``, ``E_star`` [Pa], ``d_air`` [m].
    """
    fn, v = x["normal_force"], x["voltage"]
    t = _series_thickness(p["d_air"], c)
    dgamma = 0.5 * c["eps0"] * v**2 / t
    a0 = jkr_area(fn, dgamma, p["E_star"], c["R"])
    fe = c["eps0"] * a0 * v**2 / (2.0 * c["eps_air"] * t**2)
    ft = p["mu"] * (fn + fe)
    return {"tangential_force": ft}, np.True_


def electroadhesion_empirical(p, x, c):
    """Empirical power law ``Ft = b*Fn**c + d*Fn`` (appendix eq. 16 of the electroadhesion paper).

    Parameters ``b`` [N^(1-c)], ``c_exp`` [-], ``d`` [-]; the paper fits them per voltage
    (split by the ``voltage`` column).
    """
    fn = x["normal_force"]
    ft = p["b"] * fn ** p["c_exp"] + p["d"] * fn
    return {"tangential_force": ft}, np.True_


def phi_offset(p, c):
    """Sampling shear for ``phi`` (declared in the card's ``[sampling.shear]``).

    The forces pin ``tau0*phi*dgamma`` with ``dgamma ~ 1/(t0 + d_air/eps_air)``, a curved ridge
    in (log phi, log d_air).  Sampling ``log(phi) - log(t0 + d_air/eps_air)`` instead
    straightens it (measured: max autocorrelation time 527 -> 106 steps); the map has unit
    Jacobian because the offset depends only on other parameters.
    """
    return np.log(_series_thickness(p["d_air"], c))


def air_gap_shift(c):
    """Sampling shift for ``d_air`` [m] (declared in the card's ``[sampling.shift]``).

    The data see ``d_air`` only through the stack thickness ``t = t0 + d_air/eps_air``, which
    saturates at ``t0`` for ``d_air << eps_air*t0`` (~0.27 um): ``log(d_air)`` then has a long,
    flat left tail.  Sampling ``log(d_air + eps_air*t0) = log(eps_air*t)`` instead is linear in
    ``log t`` and finite at ``d_air = 0`` (together with ``beta0`` sampled as a product: max
    autocorrelation time 90 -> 37 steps on the shipped priors).
    """
    return c["eps_air"] * (c["d_sio2"] / c["eps_sio2"] + c["d_sc"] / c["eps_sc"])
