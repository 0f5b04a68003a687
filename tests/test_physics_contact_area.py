"""Contact-area / impedance physics (Huloux, Willemet & Wiertlewski): power laws, the area-impedance law, variants."""

import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

import skinfit
from skinfit.physics.contact_area import (
    area_impedance_law,
    contact_area,
    contact_area_hertz,
    contact_area_no_levitation,
    derived,
    derived_hertz,
    derived_no_levitation,
)
from skinfit.posterior import Posterior

ROOT = Path(skinfit.__file__).resolve().parents[1]
CARD = tomllib.loads((ROOT / "datasets/contact_area_synthetic/dataset.toml").read_text())
SUBJECTS = CARD["provenance"]["subjects"]
C_HERTZ = dict(skinfit.load_model("contact_area_hertz").constants)
FA = np.repeat(np.arange(0.0, 31.0, 5.0), 5)
FN = np.tile(np.array([0.25, 0.5, 1.0, 2.0, 3.0]), 7)


def _ens(p):
    return {k: np.array([[v]]) for k, v in p.items()}


@pytest.mark.parametrize("subject", sorted(SUBJECTS))
def test_area_is_gamma_times_impedance_to_the_p(subject):
    """Section V.B: eliminating f from A = alpha*f**m and |Z| = beta*f**n gives A = gamma*|Z|**p
    with p = m/n and gamma = alpha/beta**(m/n) -- closed form against both power laws."""
    p = _ens(SUBJECTS[subject])
    x = {"normal_force": FN, "actuation_force": FA}
    y, ok = contact_area(p, x, {})
    d = derived(p, x, {})
    assert ok.all()
    np.testing.assert_allclose(y["contact_area"], d["gamma"] * y["impedance"] ** d["p"], rtol=1e-12)
    # the same from the printed coefficients at each actuation force
    s = SUBJECTS[subject]
    alpha = s["alpha_a0"] * np.exp(s["alpha_a1"] * FA)
    beta = s["beta_z0"] * np.exp(s["beta_z1"] * FA)
    m, n = s["m0"] + s["m1"] * FA, s["n_z0"] + s["n_z1"] * FA
    np.testing.assert_allclose(d["p"][0], m / n, rtol=1e-14)
    np.testing.assert_allclose(d["gamma"][0], alpha / beta ** (m / n), rtol=1e-12)
    np.testing.assert_allclose(y["contact_area"][0], alpha * FN**m, rtol=1e-12)
    np.testing.assert_allclose(y["impedance"][0], beta * FN**n, rtol=1e-12)


def test_p_falls_with_actuation_force_for_every_subject():
    """Huloux, Willemet & Wiertlewski, Fig. 6c: the exponent p decreases with f_a (m falls and n_z rises with f_a)."""
    fa = np.arange(0.0, 31.0, 5.0)
    for s in SUBJECTS.values():
        p = derived(_ens(s), {"actuation_force": fa}, {})["p"][0]
        assert np.all(np.diff(p) < 0)


def test_truths_inside_paper_ranges():
    """Per-subject truths over 0-30 N inside Huloux, Willemet & Wiertlewski's ranges over 13 subjects (Section V.A; alpha at
    f_a = 0 may exceed its 51.3 mm^2 by up to 7%, since alpha falls with f_a)."""
    fa = np.array([0.0, 30.0])
    for s in SUBJECTS.values():
        alpha_mm2 = s["alpha_a0"] * np.exp(s["alpha_a1"] * fa) * 1e6
        assert np.all((alpha_mm2 > 11.2) & (alpha_mm2 < 55))
        assert np.all((s["m0"] + s["m1"] * fa > 0.19) & (s["m0"] + s["m1"] * fa < 0.91))
        assert np.all((s["n_z0"] + s["n_z1"] * fa > 0.34) & (s["n_z0"] + s["n_z1"] * fa < 1.56))
        assert s["alpha_a1"] < 0 and s["m1"] < 0 and s["beta_z1"] < 0 and s["n_z1"] > 0


def test_hertz_variant_is_full_model_with_m_two_thirds():
    s = SUBJECTS["S03"]
    x = {"normal_force": FN, "actuation_force": FA}
    hertz = {k: v for k, v in s.items() if k not in ("m0", "m1")}
    yh, _ = contact_area_hertz(_ens(hertz), x, C_HERTZ)
    yf, _ = contact_area(_ens({**s, "m0": 2 / 3, "m1": 0.0}), x, {})
    for o in ("contact_area", "impedance"):
        np.testing.assert_allclose(yh[o], yf[o], rtol=1e-14)
    dh = derived_hertz(_ens(hertz), x, C_HERTZ)
    np.testing.assert_allclose(dh["p"][0], (2 / 3) / (s["n_z0"] + s["n_z1"] * FA), rtol=1e-14)


def test_no_levitation_variant_is_full_model_without_slopes():
    s = {"alpha_a": 30e-6, "m": 0.6, "beta_z": 3.0, "n_z": 0.8}
    x = {"normal_force": FN, "actuation_force": FA}
    yn, _ = contact_area_no_levitation(_ens(s), {"normal_force": FN}, {})
    full = {"alpha_a0": 30e-6, "alpha_a1": 0.0, "m0": 0.6, "m1": 0.0, "beta_z0": 3.0, "beta_z1": 0.0,
            "n_z0": 0.8, "n_z1": 0.0}
    yf, _ = contact_area(_ens(full), x, {})
    for o in ("contact_area", "impedance"):
        np.testing.assert_allclose(yn[o], yf[o], rtol=1e-14)
    d = derived_no_levitation(_ens(s), {}, {})
    assert d["p"].item() == pytest.approx(0.75) and d["gamma"].item() == pytest.approx(30e-6 / 3.0**0.75)


def test_vectorised_and_support(rng):
    k = 6
    p = {"alpha_a0": rng.uniform(1e-5, 6e-5, (k, 1)), "alpha_a1": rng.uniform(-0.02, 0, (k, 1)),
         "m0": rng.uniform(0.2, 0.9, (k, 1)), "m1": rng.uniform(-0.006, 0, (k, 1)),
         "beta_z0": rng.uniform(1, 8, (k, 1)), "beta_z1": rng.uniform(-0.02, 0, (k, 1)),
         "n_z0": rng.uniform(0.3, 1, (k, 1)), "n_z1": rng.uniform(0, 0.02, (k, 1))}
    x = {"normal_force": FN, "actuation_force": FA}
    y, ok = contact_area(p, x, {})
    assert y["contact_area"].shape == y["impedance"].shape == (k, FN.size)
    for i in range(k):
        yi, _ = contact_area({n: v[i, 0] for n, v in p.items()}, x, {})
        np.testing.assert_allclose(yi["contact_area"][0], y["contact_area"][i], rtol=1e-14)
    # an area exponent that turns negative at 30 N lies outside the support there
    bad = {n: v[0, 0] for n, v in p.items()} | {"m0": 0.1, "m1": -0.01}
    y, ok = contact_area(_ens(bad), x, {})
    assert np.array_equal(ok[0], FA < 10) and np.all(np.isfinite(y["contact_area"]))
    assert not contact_area(_ens(bad), {"normal_force": np.array([0.0]), "actuation_force": np.array([0.0])}, {})[1].any()


def test_area_impedance_law_closed_form():
    d = area_impedance_law(np.log(40e-6), 0.5, np.log(4.0), 1.0)
    assert d["p"] == 0.5 and d["gamma"] == pytest.approx(40e-6 / 2.0, rel=1e-14)


def test_two_lognormal_observables_each_with_own_sigma(rng):
    """The engine names the noise sigma_contact_area, sigma_impedance; the pointwise
    log-likelihood of each observable is scipy's log-normal with its own sigma."""
    ds = skinfit.load_dataset("contact_area_synthetic")
    sub = ds.subset(ds.frame["subject"] == "S02", "S02")
    post = Posterior(skinfit.load_model("contact_area"), skinfit.load_priors("contact_area"), sub)
    assert post.noise_names == ("sigma_contact_area", "sigma_impedance")
    assert post.noise == {"contact_area": "lognormal", "impedance": "lognormal"}
    theta = post.sample_prior(3, rng)
    ll, pred, _ = post.pointwise(theta)
    p = post.unpack(theta)
    for o in ("contact_area", "impedance"):
        ref = stats.lognorm.logpdf(sub.frame[o].to_numpy(), p[f"sigma_{o}"], scale=pred[o])
        np.testing.assert_allclose(ll[o], ref, rtol=1e-10)
