"""Finger pad friction on micro-textured silicone (the Biotribology 2019 paper; docs/models/textured_surface.md).

Friction coefficient of eq. 16, ``mu = tau0*A_r/F + alpha + beta_h*(9/(128*R_e))**(2/3)*(F/E0)**(1/3)``,
with the real contact area ``A_r`` of a finger pad on a square array of spherical-tipped
asperities.  skinfit reads the paper's Section 3 analytically: the numerical half-space step is
replaced by Hertz contact of each asperity (docs/models/).  Below a critical mean pressure the skin
rests on the asperity tips only; above it, a central zone of the apparent (ridge) contact
``A_ac = k_a*F**m_a`` touches the flat between the asperities (the transition of eqs. 9-14).

A flat reference sample has no texture geometry: its three texture covariates are NaN (missing
by design) and ``A_r = A_ac``.
"""

from typing import NamedTuple

import numpy as np

from skinfit.physics._cache import by_value

__all__ = [
    "reduced_modulus",
    "critical_load",
    "contact_state",
    "textured_surface",
    "textured_no_transition",
    "textured_no_hysteresis",
]

_TEXTURE = ("asperity_radius", "asperity_height", "asperity_spacing")


def reduced_modulus(E_skin, E_m, c):
    """Reduced modulus ``1/((1-nu_skin**2)/E_skin + (1-nu_m**2)/E_m)`` [Pa] (the Biotribology 2019
    paper, eqs. 3, 13)."""
    return _reduced(E_skin, _sample_compliance(E_m, c["nu_m"]), c)


def _sample_compliance(E_m, nu_m):
    return (1.0 - nu_m**2) / E_m


def _reduced(E_skin, c_m, c):
    """:func:`reduced_modulus` with the sample's term ``(1-nu_m**2)/E_m`` = ``c_m`` given."""
    return 1.0 / ((1.0 - c["nu_skin"] ** 2) / E_skin + c_m)


def critical_load(E_skin_micro, sample_modulus, asperity_radius, asperity_height, asperity_spacing,
                  k_a, m_a, c):
    """Normal load F_crit [N] at which the transition to full contact starts (eq. 14, the Biotribology 2019 paper).

    Eq. 14, ``F_crit = 8*sqrt(h**3*R_asp)/(9*lambda**2) * A_ac * E1``, with the apparent area
    ``A_ac = k_a*F_crit**m_a`` evaluated at F_crit itself, solved in closed form:
    ``F_crit = (8*sqrt(h**3*R_asp)*k_a*E1/(9*lambda**2))**(1/(1 - m_a))`` (needs ``m_a < 1``).
    All arguments broadcast; SI units.
    """
    e1 = reduced_modulus(E_skin_micro, sample_modulus, c)
    g = 8.0 * np.sqrt(asperity_height**3 * asperity_radius) / (9.0 * asperity_spacing**2) * k_a * e1
    return g ** (1.0 / (1.0 - m_a))


def contact_state(p, x, c, *, transition=True, pressures=True):
    """Contact areas and pressures of the analytic reading of the Biotribology 2019 paper, Section 3.

    Parameters ``E_skin_micro`` [Pa], ``k_a`` [m^2/N^m_a], ``m_a`` [-] (arrays broadcastable to
    (k, n)); covariates ``normal_force`` F [N], ``sample_modulus`` [Pa], ``asperity_radius``,
    ``asperity_height``, ``asperity_spacing`` [m] (NaN on a flat reference), each (n,).

    Returns a dict of (k, n) arrays: ``A_ac`` apparent area [m^2]; ``pbar`` mean apparent
    pressure F/A_ac [Pa]; ``x`` the full-contact fraction A_trans/A_ac (eq. 9; 0 when
    ``transition`` is False and on a flat reference); ``p_trans``, ``p_asp`` mean pressures of
    the full-contact and asperity zones [Pa] (eqs. 11-12 in closed form: pbar*(1-(1-x)**1.5)/x
    and pbar*sqrt(1-x); p_trans = 1.5*pbar as x -> 0; omitted when ``pressures`` is False, as
    the friction needs neither); ``A_r`` real contact area [m^2]; and ``flat`` (bool, (n,)) and
    ``ok`` (bool, (n,): texture geometry either complete or all missing, and F > 0), both
    read-only (cached with the covariates).
    """
    return _contact(p, _covariate_terms(x, c), c, transition=transition, pressures=pressures)


class _Terms(NamedTuple):
    """What :func:`contact_state` needs of the covariates alone, each (n,) (see :func:`_terms`)."""

    f: np.ndarray  # normal force [N], 1 where F <= 0
    log_f: np.ndarray
    flat: np.ndarray  # flat reference (texture geometry all missing)
    ok: np.ndarray  # texture geometry complete or all missing, and F > 0
    any_flat: np.ndarray  # 0-d
    crit: np.ndarray  # (8/9)*sqrt(R_asp)*h**1.5/lambda**2 (eq. 9); NaN texture filled with 1
    hertz: np.ndarray  # 0.75*lambda**2*R_asp (eq. 12)
    cell_scale: np.ndarray  # pi/lambda**2
    c_m: np.ndarray  # (1 - nu_m**2)/E_m [1/Pa]


def _covariate_terms(x, c):
    return _terms(*(x[k] for k in ("normal_force", "sample_modulus") + _TEXTURE), scalars=(float(c["nu_m"]),))


def _contact(p, t, c, *, transition, pressures):
    """:func:`contact_state` from the covariates' terms ``t`` (:class:`_Terms`)."""
    f_safe, log_f, flat, ok, any_flat, crit, hertz, cell_scale, c_m = t
    e1 = _reduced(p["E_skin_micro"], c_m, c)
    a_ac = p["k_a"] * np.exp(p["m_a"] * log_f)  # k_a*F**m_a; log F has no parameter axes
    pbar = f_safe / a_ac
    if transition:
        # 2*F_crit/(3*F_i): F_crit = (4/3)*E1*sqrt(R_asp)*h**1.5 (Hertz at indentation h, eq. 13),
        # F_i = pbar*lambda**2 (mean force per asperity, eq. 6)
        s = e1 * crit / pbar
        frac = np.clip(1.0 - s * s, 0.0, 1.0)  # eq. 9
    else:
        frac = np.zeros(np.broadcast_shapes(np.shape(pbar), np.shape(e1)))
    if any_flat:  # the np.where passes only where a flat reference exists
        frac = np.where(flat, 0.0, frac)
    one_minus = 1.0 - frac
    p_asp = pbar * np.sqrt(one_minus)  # eq. 12
    a_i = np.cbrt(p_asp * hertz / e1)  # Hertz radius of one asperity contact
    cell = np.minimum(1.0, a_i * a_i * cell_scale)
    share = frac + one_minus * cell  # real area / apparent area
    a_r = a_ac * (np.where(flat, 1.0, share) if any_flat else share)
    out = {"A_ac": a_ac, "pbar": pbar, "x": frac, "p_asp": p_asp, "A_r": a_r, "flat": flat, "ok": ok}
    if pressures:
        with np.errstate(divide="ignore", invalid="ignore"):
            out["p_trans"] = np.where(frac > 0, pbar * (1.0 - one_minus**1.5) / frac, 1.5 * pbar)  # eq. 11
    return out


@by_value
def _terms(f, sample_modulus, r_asp, h, lam, nu_m):
    """:class:`_Terms` of the covariates, cached by their values."""
    missing = [np.isnan(g) for g in (r_asp, h, lam)]
    flat = missing[0] & missing[1] & missing[2]
    ok = (missing[0] == missing[1]) & (missing[1] == missing[2]) & (f > 0)
    r_asp, h, lam = (np.where(m, 1.0, g) for m, g in zip(missing, (r_asp, h, lam)))  # harmless fill
    f_safe = np.where(f > 0, f, 1.0)
    lam2 = lam**2
    return _Terms(f_safe, np.log(f_safe), flat, ok, np.asarray(flat.any()),
                  (8.0 / 9.0) * np.sqrt(r_asp) * h**1.5 / lam2,
                  0.75 * lam2 * r_asp, np.pi / lam2, _sample_compliance(sample_modulus, nu_m))


def _friction(p, x, c, *, transition, hysteresis):
    t = _covariate_terms(x, c)
    s = _contact(p, t, c, transition=transition, pressures=False)
    mu = p["tau0"] * s["A_r"] / t.f + p["alpha"]
    if hysteresis:
        e0 = _reduced(p["E_fingerpad"], t.c_m, c)
        mu = mu + p["beta_h"] * (9.0 / (128.0 * c["R_e"])) ** (2.0 / 3.0) * np.cbrt(t.f / e0)  # eq. 15/F
    return {"friction_coefficient": np.atleast_2d(np.where(s["ok"], mu, 0.0))}, s["ok"]


def textured_surface(p, x, c):
    """Dynamic friction coefficient [-] of a finger pad on textured silicone (eq. 16, the Biotribology 2019 paper).

    Parameters ``E_skin_micro`` [Pa], ``E_fingerpad`` [Pa], ``tau0`` [Pa], ``alpha`` [-],
    ``beta_h`` [-], ``k_a`` [m^2/N^m_a], ``m_a`` [-]; covariates ``normal_force`` [N],
    ``sample_modulus`` [Pa] and the texture geometry [m] (NaN on a flat reference); constants
    ``R_e`` [m], ``nu_skin``, ``nu_m``.  Outside the support: F <= 0, or a row whose texture
    geometry is only partly given.
    """
    return _friction(p, x, c, transition=True, hysteresis=True)


def textured_no_transition(p, x, c):
    """As :func:`textured_surface` with the skin on the asperity tips at every load (x = 0)."""
    return _friction(p, x, c, transition=False, hysteresis=True)


def textured_no_hysteresis(p, x, c):
    """As :func:`textured_surface` without the hysteresis term (beta_h = 0; no ``E_fingerpad``)."""
    return _friction(p, x, c, transition=True, hysteresis=False)
