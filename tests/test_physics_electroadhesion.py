"""Electroadhesion physics against the paper's numbers and closed forms (the electroadhesion paper)."""

import numpy as np
import pytest

import skinfit
from skinfit.physics.electroadhesion import adhesion_energy, electroadhesion, jkr_area

C = dict(skinfit.load_model("electroadhesion").constants)
TABLE_I = {"E_star": 35e3, "tau0": 10.64e3, "d_air": 0.19e-6, "beta0": 0.0049, "phi": 0.47,
           "eta": 3.72e-4}


def test_adhesion_energy_section_ii():
    # the electroadhesion paper, Section II: dgamma ~ 0.035 J/m^2 at V = 100 V and d_air = 1 um
    assert adhesion_energy(100.0, 1e-6, C) == pytest.approx(0.035, rel=0.02)


def test_pull_off_force_section_ii():
    # pull-off force -1.5*dgamma*pi*R ~ -3.3 mN; the JKR radicand vanishes exactly there
    dg = adhesion_energy(100.0, 1e-6, C)
    f_pull = -1.5 * dg * np.pi * C["R"]
    assert f_pull == pytest.approx(-3.3e-3, rel=0.02)
    assert 6 * dg * np.pi * C["R"] * f_pull + (3 * dg * np.pi * C["R"]) ** 2 == pytest.approx(0, abs=1e-15)
    # JKR radius at pull-off: a^3 = (3R/4E)(F + 3 dgamma pi R) = (3R/4E)(1.5 dgamma pi R)
    E = 35e3
    a3 = 3 * C["R"] / (4 * E) * 1.5 * dg * np.pi * C["R"]
    assert jkr_area(f_pull, dg, E, C["R"]) == pytest.approx(np.pi * a3 ** (2 / 3), rel=1e-9)


@pytest.mark.parametrize("fn", [0.2, 1.0, 2.0])
def test_jkr_reduces_to_hertz(fn):
    E, R = 35e3, C["R"]
    hertz = np.pi * (3 * R * fn / (4 * E)) ** (2 / 3)
    assert jkr_area(fn, 0.0, E, R) == pytest.approx(hertz, rel=1e-14)


def _implicit_residual(p, fn, v, ft):
    dg = adhesion_energy(v, p["d_air"], C)
    a0 = jkr_area(fn, dg, p["E_star"], C["R"])
    b = p["tau0"] * (p["beta0"] + p["phi"] * dg)
    return ft - (b * (a0 - p["eta"] * ft**2) + p["alpha"] * fn)


def test_closed_form_root_solves_implicit_equation(rng):
    k, n = 500, 40
    p = {"E_star": rng.uniform(2e3, 1e5, (k, 1)), "tau0": rng.uniform(100, 15e3, (k, 1)),
         "d_air": 10 ** rng.uniform(-9, -5.3, (k, 1)), "beta0": 10 ** rng.uniform(-4, 0, (k, 1)),
         "phi": 10 ** rng.uniform(-3, 0, (k, 1)), "eta": 10 ** rng.uniform(-12, 0, (k, 1)),
         "alpha": rng.uniform(0, 1.5, (k, 1))}
    x = {"normal_force": rng.uniform(0.2, 2, n), "voltage": rng.choice([0.0, 50, 100, 200], n)}
    y, ok = electroadhesion(p, x, C)
    ft = y["tangential_force"]
    assert ft.shape == (k, n) and np.all(np.isfinite(ft))
    res = _implicit_residual(p, x["normal_force"], x["voltage"], ft)
    assert np.max(np.abs(res) / ft) < 1e-12
    assert ok.any() and (~ok).any()  # both inside and outside the support were exercised


def test_root_at_b_eta_zero_limit():
    p = {**TABLE_I, "alpha": 0.5}
    x = {"normal_force": np.array([0.5, 1.0]), "voltage": np.array([100.0, 100.0])}
    for eta in [0.0, 1e-300, 1e-30, 1e-16]:
        y, _ = electroadhesion({**p, "eta": eta}, x, C)
        dg = adhesion_energy(100.0, p["d_air"], C)
        c = p["tau0"] * (p["beta0"] + p["phi"] * dg) * jkr_area(x["normal_force"], dg, p["E_star"], C["R"]) \
            + p["alpha"] * x["normal_force"]
        # Ft = c when B*eta = 0, and Ft = c - B*eta*c^2 + O(eta^2) near it
        assert np.allclose(y["tangential_force"], c, rtol=max(1e-12, 1e4 * eta))


def test_table_i_point_leaves_support_near_2N():
    # docs/models/electroadhesion.md: the paper's Table I point gives A_app < 0 near Fn = 2 N when alpha ~ 0.5
    x = {"normal_force": np.array([0.2, 2.0]), "voltage": np.array([0.0, 0.0])}
    y, ok = electroadhesion({**TABLE_I, "alpha": 0.5}, x, C)
    assert ok.tolist() == [True, False]
    assert np.all(np.isfinite(y["tangential_force"]))


def test_predict_broadcasts_ensemble_against_rows():
    model = skinfit.load_model("electroadhesion")
    data = {"normal_force": np.linspace(0.2, 2, 7), "voltage": np.full(7, 100.0)}
    k = 5
    params = {**{n: np.full(k, v) for n, v in TABLE_I.items()}, "eta": np.linspace(1e-5, 1e-4, k),
              "alpha": np.full(k, 0.4)}
    y = model.predict(params, data)
    assert y.shape == (k, 7)
    for i in range(k):
        yi = model.predict({n: float(v[i]) for n, v in params.items()}, data)
        assert yi.shape == (7,)
        np.testing.assert_allclose(y[i], yi, rtol=1e-15)


def test_predict_outside_support_warns_and_is_nan():
    model = skinfit.load_model("electroadhesion")
    data = {"normal_force": np.array([0.2, 2.0]), "voltage": np.array([0.0, 0.0])}
    with pytest.warns(skinfit.SupportWarning, match="outside the physical support"):
        y = model.predict({**TABLE_I, "alpha": 0.5}, data)
    assert np.isfinite(y[0]) and np.isnan(y[1])


def test_forces_see_only_the_products_the_sampler_uses(rng):
    """The two exact symmetries behind the card's [sampling.product] (models/electroadhesion.toml):
    E* -> l*E*, tau0 -> l^(2/3)*tau0, eta -> l^(-2/3)*eta and tau0 -> m*tau0, beta0 -> beta0/m,
    phi -> phi/m leave every force and the support unchanged (A0 ~ E*^(-2/3) in eq. 6)."""
    x = {"normal_force": rng.uniform(0.2, 2.0, 50), "voltage": rng.choice([0.0, 50.0, 100.0, 150.0], 50)}
    p = {k: np.array([[v]]) for k, v in TABLE_I.items()} | {"alpha": np.array([[0.45]])}
    ft, ok = electroadhesion(p, x, C)
    for lam, mu in [(3.0, 1.0), (1.0, 0.4), (0.2, 2.5)]:
        q = dict(p, E_star=p["E_star"] * lam, tau0=p["tau0"] * lam ** (2 / 3) * mu, eta=p["eta"] * lam ** (-2 / 3),
                 beta0=p["beta0"] / mu, phi=p["phi"] / mu)
        ft2, ok2 = electroadhesion(q, x, C)
        np.testing.assert_allclose(ft2["tangential_force"], ft["tangential_force"], rtol=1e-12)
        assert np.array_equal(ok2, ok)
