"""Real contact area and ultrasonic impedance of a fingertip pressing on glass (Huloux, Willemet &
Wiertlewski; docs/models/contact_area.md).

Two power laws of the normal force f per press (eqs. 3 and 4 of Huloux, Willemet & Wiertlewski)::

    A   = alpha_a * f**m          optical real contact area [m^2]
    |Z| = beta_z  * f**n_z        impedance modulus [N*s/m]

whose coefficients depend on the ultrasonic actuation force f_a [N] (squeeze-film levitation):
``log(alpha_a)``, ``m``, ``log(beta_z)`` and ``n_z`` are each linear in f_a.  Eliminating f gives
the paper's area-impedance law ``A = gamma*|Z|**p`` with ``p = m/n_z`` and
``gamma = alpha_a/beta_z**(m/n_z)`` (Section V.B), reported by :func:`derived`.

Parameters of :func:`contact_area` (intercepts at f_a = 0, slopes per newton of f_a):
``alpha_a0`` [m^2/N^m], ``alpha_a1`` [1/N] (slope of log alpha_a), ``m0`` [-], ``m1`` [1/N],
``beta_z0`` [N*s/m / N^n_z], ``beta_z1`` [1/N] (slope of log beta_z), ``n_z0`` [-], ``n_z1`` [1/N].
"""

import numpy as np

__all__ = [
    "contact_area",
    "contact_area_hertz",
    "contact_area_no_levitation",
    "derived",
    "derived_hertz",
    "derived_no_levitation",
    "area_impedance_law",
]


def _levitation(p, fa):
    """(log alpha_a, m, log beta_z, n_z), each linear in the actuation force ``fa`` [N]."""
    return (np.log(p["alpha_a0"]) + p["alpha_a1"] * fa, p["m0"] + p["m1"] * fa,
            np.log(p["beta_z0"]) + p["beta_z1"] * fa, p["n_z0"] + p["n_z1"] * fa)


def _hertz(p, fa, c):
    """As :func:`_levitation` with the area exponent fixed at the Hertz value ``c['m_hertz']``."""
    log_a, _, log_b, n = _levitation({**p, "m0": 0.0, "m1": 0.0}, fa)
    return log_a, np.full(np.broadcast_shapes(np.shape(log_a), np.shape(n)), c["m_hertz"]), log_b, n


def _constant(p):
    """Coefficients that do not depend on the actuation force."""
    return np.log(p["alpha_a"]), p["m"], np.log(p["beta_z"]), p["n_z"]


def _observe(coef, x):
    log_a, m, log_b, n = coef
    f = np.asarray(x["normal_force"], dtype=float)
    positive = f > 0
    log_f = np.log(np.where(positive, f, 1.0))
    ok = (m > 0) & (n > 0) & positive
    area = np.atleast_2d(np.exp(log_a + m * log_f))
    impedance = np.atleast_2d(np.exp(log_b + n * log_f))
    if area.shape != impedance.shape:  # one of them not varying with the ensemble
        shape = np.broadcast_shapes(area.shape, impedance.shape)
        area, impedance = np.broadcast_to(area, shape), np.broadcast_to(impedance, shape)
    return {"contact_area": area, "impedance": impedance}, ok


def area_impedance_law(log_alpha_a, m, log_beta_z, n_z):
    """``{gamma, p}`` of ``A = gamma*|Z|**p``: ``p = m/n_z``, ``gamma = alpha_a/beta_z**(m/n_z)``.

    ``gamma`` is in m^2 / (N*s/m)**p; arguments broadcast (``n_z`` must be > 0).
    """
    p = m / n_z
    return {"gamma": np.exp(log_alpha_a - p * log_beta_z), "p": p}


def contact_area(p, x, c):
    """Contact area [m^2] and impedance modulus [N*s/m] per press (eqs. 3-4 of Huloux, Willemet & Wiertlewski).

    Covariates ``normal_force`` f [N] and ``actuation_force`` f_a [N], each (n,); parameters
    as in the module docstring, (k, 1) or (k, n).  Outside the support: ``m <= 0`` or
    ``n_z <= 0`` at an observed f_a, or f <= 0.
    """
    return _observe(_levitation(p, x["actuation_force"]), x)


def contact_area_hertz(p, x, c):
    """As :func:`contact_area` with the area exponent fixed at the Hertz value m = 2/3 (constant ``m_hertz``)."""
    return _observe(_hertz(p, x["actuation_force"], c), x)


def contact_area_no_levitation(p, x, c):
    """No dependence on the actuation force: parameters ``alpha_a``, ``m``, ``beta_z``, ``n_z``."""
    return _observe(_constant(p), x)


def derived(p, x, c):
    """``gamma`` and ``p`` of A = gamma*|Z|**p at each row's actuation force (model :func:`contact_area`)."""
    log_a, m, log_b, n = _levitation(p, x["actuation_force"])
    return area_impedance_law(log_a, m, log_b, n)


def derived_hertz(p, x, c):
    """``gamma`` and ``p`` for :func:`contact_area_hertz`."""
    return area_impedance_law(*_hertz(p, x["actuation_force"], c))


def derived_no_levitation(p, x, c):
    """``gamma`` and ``p`` for :func:`contact_area_no_levitation` (the same at every f_a)."""
    return area_impedance_law(*_constant(p))
