"""Textured-surface physics (the Biotribology 2019 paper) against the paper's equations and closed forms."""

import numpy as np
import pytest
from scipy import integrate, optimize

import skinfit
from skinfit.physics.textured import (
    contact_state,
    critical_load,
    reduced_modulus,
    textured_no_hysteresis,
    textured_no_transition,
    textured_surface,
)

C = dict(skinfit.load_model("textured_surface").constants)
# the Biotribology 2019 paper Table 1: (R_asp, h, lambda) [m] and E_m [Pa] of the eight textured samples
TABLE_1 = [(18.8e-6, 27.9e-6, 200e-6, 0.20e6), (18.8e-6, 28.9e-6, 200e-6, 0.75e6),
           (18.4e-6, 28.8e-6, 200e-6, 1.30e6), (18.4e-6, 27.1e-6, 200e-6, 2.30e6),
           (20.4e-6, 27.7e-6, 100e-6, 0.20e6), (20.1e-6, 28.1e-6, 100e-6, 0.75e6),
           (19.7e-6, 28.3e-6, 100e-6, 1.30e6), (19.9e-6, 28.0e-6, 100e-6, 2.30e6)]
PAPER = {"E_skin_micro": 0.2e6, "E_fingerpad": 40e3, "tau0": 8e3, "alpha": 0.35, "beta_h": 0.3,
         "k_a": 85e-6, "m_a": 0.49}  # Section 4.3: E 0.2 MPa, alpha 0.35, A_a ~ 85 mm^2 F^0.49


def _ens(p):
    """One parameter vector as the engine passes it: arrays of shape (1, 1)."""
    return {k: np.array([[v]]) for k, v in p.items()}


def _rows(f, sample):
    r, h, lam, em = sample
    n = np.size(f)
    return {"normal_force": np.atleast_1d(np.asarray(f, dtype=float)), "sample_modulus": np.full(n, em),
            "asperity_radius": np.full(n, r), "asperity_height": np.full(n, h), "asperity_spacing": np.full(n, lam)}


def _flat(f, em):
    n = np.size(f)
    return {"normal_force": np.asarray(f, dtype=float), "sample_modulus": np.full(n, em),
            **{k: np.full(n, np.nan) for k in ("asperity_radius", "asperity_height", "asperity_spacing")}}


@pytest.mark.parametrize("sample", TABLE_1)
@pytest.mark.parametrize("e_skin", [0.2e6, 0.5e6])
def test_eq14_critical_load_is_where_the_transition_starts(sample, e_skin):
    """x = A_trans/A_ac leaves 0 exactly at F_crit of eq. 14 (found by bisection of the model)."""
    r, h, lam, em = sample
    p = {**PAPER, "E_skin_micro": e_skin}
    f_crit = critical_load(e_skin, em, r, h, lam, p["k_a"], p["m_a"], C)

    def starts(f):
        return contact_state(_ens(p), _rows(f, sample), C)["x"][0, 0] > 0

    f_bisect = optimize.bisect(lambda f: 1.0 if starts(f) else -1.0, 1e-6, 1e3, xtol=1e-15, rtol=1e-13)
    assert f_bisect == pytest.approx(f_crit, rel=1e-10)
    # eq. 14 as printed, with A_ac evaluated at F_crit
    e1 = reduced_modulus(e_skin, em, C)
    a_ac = p["k_a"] * f_crit ** p["m_a"]
    assert f_crit == pytest.approx(8 * np.sqrt(h**3 * r) / (9 * lam**2) * a_ac * e1, rel=1e-12)
    # eq. 13: at F_crit the peak asperity force 1.5*F_i indents skin + asperity by exactly h
    f_i_crit = 1.5 * f_crit / a_ac * lam**2
    assert (9 * f_i_crit**2 / (16 * e1**2 * r)) ** (1 / 3) == pytest.approx(h, rel=1e-12)


def test_l200_transitions_before_l100():
    """Fig. 4b: the denser L100 texture needs a 4x larger mean pressure to make full contact."""
    for l200, l100 in zip(TABLE_1[:4], TABLE_1[4:]):
        f200 = critical_load(0.3e6, l200[3], *l200[:3], 85e-6, 0.49, C)
        f100 = critical_load(0.3e6, l100[3], *l100[:3], 85e-6, 0.49, C)
        assert f100 > 3 * f200


@pytest.mark.parametrize("x_frac", [0.01, 0.3, 0.7, 0.99])
def test_zone_pressures_integrate_the_hertz_profile_and_sum_to_F(x_frac):
    """Eqs. 11-12 by quadrature of p(r) = 1.5*pbar*sqrt(1 - r^2/a_ac^2) (eq. 7) against the
    closed forms; the two zones carry the whole load F."""
    sample = TABLE_1[1]
    r, h, lam, em = sample
    e1 = reduced_modulus(PAPER["E_skin_micro"], em, C)
    f_i_crit = (4 / 3) * e1 * np.sqrt(r) * h**1.5
    # choose F so that eq. 9 gives x_frac: F_i = 2*F_i_crit/(3*sqrt(1 - x)), F_i = F/A_ac * lam^2
    f_i = 2 * f_i_crit / (3 * np.sqrt(1 - x_frac))
    f = optimize.brentq(lambda f: f / (PAPER["k_a"] * f ** PAPER["m_a"]) * lam**2 - f_i, 1e-6, 1e4, xtol=1e-14)
    s = contact_state(_ens(PAPER), _rows(f, sample), C)
    assert s["x"][0, 0] == pytest.approx(x_frac, rel=1e-9)
    pbar, a_ac = s["pbar"][0, 0], s["A_ac"][0, 0]
    a = np.sqrt(a_ac / np.pi)
    a_t = a * np.sqrt(x_frac)  # eq. 10

    def profile(rr):
        return 1.5 * pbar * np.sqrt(max(0.0, 1 - rr**2 / a**2)) * 2 * np.pi * rr

    p_trans = integrate.quad(profile, 0, a_t, epsabs=0, epsrel=1e-12)[0] / (np.pi * a_t**2)
    p_asp = integrate.quad(profile, a_t, a, epsabs=0, epsrel=1e-12)[0] / (np.pi * (a**2 - a_t**2))
    assert s["p_trans"][0, 0] == pytest.approx(p_trans, rel=1e-8)
    assert s["p_asp"][0, 0] == pytest.approx(p_asp, rel=1e-8)
    total = s["p_trans"][0, 0] * x_frac * a_ac + s["p_asp"][0, 0] * (1 - x_frac) * a_ac
    assert total == pytest.approx(f, rel=1e-12)


def test_flat_reference_is_eq16_with_apparent_area():
    """Flat rows (texture NaN by design): A_r = A_ac, mu = tau0*A_ac/F + alpha + F_def/F (eqs. 15, 16)."""
    f = np.array([0.1, 0.5, 1.0, 2.0, 5.0])
    y, ok = textured_surface(PAPER, _flat(f, 0.75e6), C)
    e0 = 1 / ((1 - C["nu_skin"] ** 2) / PAPER["E_fingerpad"] + (1 - C["nu_m"] ** 2) / 0.75e6)
    f_def = PAPER["beta_h"] * (9 / (128 * C["R_e"])) ** (2 / 3) * (f**4 / e0) ** (1 / 3)  # eq. 15
    mu = PAPER["tau0"] * PAPER["k_a"] * f ** PAPER["m_a"] / f + PAPER["alpha"] + f_def / f
    assert ok.all()
    np.testing.assert_allclose(y["friction_coefficient"][0], mu, rtol=1e-13)


def test_asperity_only_state_is_hertz_of_each_asperity():
    """Below F_crit: A_r = A_ac * pi*a^2/lambda^2 with a^3 = 3*F_i*R_asp/(4*E1), F_i = F*lambda^2/A_ac."""
    sample = TABLE_1[7]  # L100 M60: no transition below ~1 N
    r, h, lam, em = sample
    f = np.array([0.1, 0.2, 0.4])
    assert f.max() < critical_load(PAPER["E_skin_micro"], em, r, h, lam, PAPER["k_a"], PAPER["m_a"], C)
    s = contact_state(_ens(PAPER), _rows(f, sample), C)
    a_ac = PAPER["k_a"] * f ** PAPER["m_a"]
    a = (3 * f * lam**2 / a_ac * r / (4 * reduced_modulus(PAPER["E_skin_micro"], em, C))) ** (1 / 3)
    np.testing.assert_allclose(s["A_r"][0], a_ac * np.pi * a**2 / lam**2, rtol=1e-13)
    np.testing.assert_array_equal(s["x"][0], 0.0)


def test_variants_reduce():
    f = np.geomspace(0.1, 5, 19)
    for sample in TABLE_1:
        x = _rows(f, sample)
        full, _ = textured_surface(PAPER, x, C)
        # no_hysteresis = full model with beta_h = 0
        nh, _ = textured_no_hysteresis({k: v for k, v in PAPER.items() if k not in ("beta_h", "E_fingerpad")}, x, C)
        zero, _ = textured_surface({**PAPER, "beta_h": 0.0}, x, C)
        np.testing.assert_allclose(nh["friction_coefficient"], zero["friction_coefficient"], rtol=1e-14)
        # no_transition: x = 0 everywhere; identical below F_crit, smaller area above it
        nt, _ = textured_no_transition(PAPER, x, C)
        assert np.all(contact_state(PAPER, x, C, transition=False)["x"] == 0)
        f_crit = critical_load(PAPER["E_skin_micro"], sample[3], *sample[:3], PAPER["k_a"], PAPER["m_a"], C)
        below = f <= f_crit
        np.testing.assert_allclose(nt["friction_coefficient"][0, below], full["friction_coefficient"][0, below], rtol=1e-14)
        assert np.all(nt["friction_coefficient"][0, ~below] < full["friction_coefficient"][0, ~below])
    # on a flat reference the transition plays no part
    flat = _flat(f, 1.3e6)
    np.testing.assert_array_equal(textured_no_transition(PAPER, flat, C)[0]["friction_coefficient"],
                                  textured_surface(PAPER, flat, C)[0]["friction_coefficient"])


def test_vectorised_over_ensemble_and_split_rows(rng):
    k = 7
    f = np.tile(np.geomspace(0.1, 5, 6), 3)
    x = {key: np.concatenate([_rows(f[:6], TABLE_1[1])[key], _rows(f[:6], TABLE_1[6])[key], _flat(f[:6], 2.3e6)[key]])
         for key in _rows(f[:6], TABLE_1[1])}
    p = {"E_skin_micro": rng.uniform(0.1e6, 1e6, (k, 1)), "E_fingerpad": rng.uniform(1e4, 1e5, (k, 1)),
         "tau0": rng.uniform(1e3, 2e4, (k, 1)), "alpha": rng.uniform(0, 1, (k, 1)),
         "beta_h": rng.uniform(0, 1, (k, len(f))),  # split by material: one value per row
         "k_a": rng.uniform(3e-5, 2e-4, (k, 1)), "m_a": rng.uniform(0.2, 0.7, (k, 1))}
    y, ok = textured_surface(p, x, C)
    assert y["friction_coefficient"].shape == (k, len(f)) and np.all(ok)
    for i in range(k):
        for j in range(len(f)):
            pij = {n: v[i, j] if v.shape[1] > 1 else v[i, 0] for n, v in p.items()}
            yij, _ = textured_surface(pij, {n: v[j:j + 1] for n, v in x.items()}, C)
            assert yij["friction_coefficient"][0, 0] == pytest.approx(y["friction_coefficient"][i, j], rel=1e-13)


def test_support_partial_geometry_and_zero_load():
    x = _rows([1.0, 1.0, 0.0], TABLE_1[0])
    x["asperity_height"][1] = np.nan  # geometry only partly given
    y, ok = textured_surface(PAPER, x, C)
    assert ok.tolist() == [True, False, False]
    assert np.all(np.isfinite(y["friction_coefficient"]))
