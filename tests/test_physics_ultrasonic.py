"""Ultrasonic friction models (seed 004; MODELS.md section 5): limits, the paper's peak, the
period quadrature's convergence, variants, vectorisation, the shipped dataset and recovery."""

import importlib.util
import math
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest

import skinfit
from recovery import check_coverage
from skinfit.physics import ultrasonic as us

ROOT = Path(skinfit.__file__).resolve().parents[1]
DATA = ROOT / "datasets" / "ultrasonic_synthetic"
PAPER = dict(mu_inf=1.86, mu_0=0.156, k_V=0.0048, q=0.0177, V0=0.068)  # seed 004, Fig. 2 fit


def _p(**kw):
    return {k: np.array([[v]]) for k, v in {**PAPER, **kw}.items()}


def _x(v, angle=math.pi / 2, amp=0.0, f=58e3):
    v = np.atleast_1d(np.asarray(v, dtype=float))
    return {"velocity": v, "direction_angle": np.full(v.size, angle), "amplitude_pp": np.full(v.size, amp),
            "frequency": np.full(v.size, f)}


def _mu(model, v, **kw):
    return getattr(us, model)(_p(**{k: w for k, w in kw.items() if k in PAPER or k == "mu_plus"}),
                              _x(v, **{k: w for k, w in kw.items() if k in ("angle", "amp")}), {})[0][
        "friction_coefficient"][0]


def test_zero_speed_limit():
    """Vs -> 0: the bracket behaves like Vs, so mu_E -> 2*mu*(q+1)/(1+q)*Vs = 2*mu*Vs."""
    for v in (1e-9, 1e-6, 1e-4):
        mu = us.mu_equilibrium(np.array(v), 1.0, 0.0177, 0.068)
        assert mu == pytest.approx(2 * v / 0.068, rel=1e-6)
    assert us.mu_equilibrium(np.array(0.0), 1.0, 0.0177, 0.068) == 0.0


def test_high_speed_branch_is_continuous():
    """The series used for small 1/Vs matches the direct formula in extended precision on both
    sides of the switch (no jump, no cancellation)."""
    u = np.array([1e-4, 1e-3, 0.009999, 0.010001, 0.05])
    direct = -np.expm1(-u.astype(np.longdouble)) / u - np.exp(-u.astype(np.longdouble))
    assert np.allclose(us._bracket(u), direct.astype(float), rtol=1e-9)


def test_no_vibration_peak_lies_between_20_and_60_mm_s():
    v = np.linspace(0.005, 0.2, 391)
    mu = _mu("ultrasonic", v)
    assert 0.020 < v[np.argmax(mu)] < 0.060
    assert np.all(np.isfinite(mu))


@pytest.mark.parametrize("angle", [0.0, 0.7, math.pi / 2, math.pi])
def test_period_quadrature_converges(angle):
    v, amp = np.meshgrid(np.linspace(0.02, 0.14, 13), np.linspace(0, 1.6e-6, 9))

    def f(speed, vx, vy, rows):
        return us.mu_equilibrium(speed, us.mu_speed(speed, 1.86, 0.156, 0.0048), 0.0177, 0.068)

    args = (v.ravel(), np.full(v.size, angle), amp.ravel(), np.full(v.size, 58e3))
    once = us.period_average(f, *args, m=us.PHASES)
    twice = us.period_average(f, *args, m=2 * us.PHASES)
    assert np.max(np.abs(once - twice)) < 1e-6


def test_period_average_of_a_known_function():
    """Mean of |v_x| over a period for motion along the axis: closed form with the kink."""
    vf, amp = 0.03, math.pi * 58e3 * 1.0e-6
    c = vf / amp
    exact = (2 / math.pi) * (vf * math.asin(c) + amp * math.sqrt(1 - c * c))
    got = us.period_average(lambda s, vx, vy, rows: s, np.array([vf]), np.array([0.0]), np.array([1.0e-6]),
                            np.array([58e3]))
    assert got[0] == pytest.approx(exact, rel=1e-10)


@pytest.mark.parametrize("v, angle, amp", [(0.03, 0.0, 1.6e-6), (0.1, 0.0, 0.4e-6), (0.06, math.pi / 2, 1.6e-6),
                                           (0.02, 0.4, 1.2e-6), (0.14, 1.2, 0.8e-6)])
def test_period_average_agrees_with_adaptive_quadrature(v, angle, amp):
    """The model's prediction equals the period average of eq. 5 done independently by
    scipy's adaptive quad over the whole period, told where v_x changes sign."""
    from scipy.integrate import quad

    omega = 2 * math.pi * 58e3
    vx0, vy = v * math.cos(angle), v * math.sin(angle)

    def mu_of_t(t):
        speed = math.hypot(vx0 - omega * amp / 2 * math.cos(omega * t), vy)
        star = us.mu_speed(speed, PAPER["mu_inf"], PAPER["mu_0"], PAPER["k_V"])
        return float(us.mu_equilibrium(np.array(speed), star, PAPER["q"], PAPER["V0"]))

    period = 1 / 58e3
    c = vx0 / (omega * amp / 2)
    kinks = [math.acos(c) / omega, period - math.acos(c) / omega] if abs(c) < 1 else None
    exact = quad(mu_of_t, 0, period, points=kinks, epsabs=1e-13, epsrel=1e-12, limit=200)[0] / period
    assert _mu("ultrasonic", v, angle=angle, amp=amp)[0] == pytest.approx(exact, abs=1e-8)  # measured: <= 4.2e-9


def test_variants_agree_without_vibration():
    v = np.linspace(0.02, 0.14, 7)
    full = _mu("ultrasonic", v)
    assert np.allclose(_mu("ultrasonic_projected", v), full, rtol=1e-12)  # v_r along u_f: factor 1
    star = us.mu_speed(0.06, PAPER["mu_inf"], PAPER["mu_0"], PAPER["k_V"])
    assert _mu("ultrasonic_constant_mu", 0.06, mu_plus=star) == pytest.approx(_mu("ultrasonic", 0.06), rel=1e-12)


def test_vibration_across_motion_lowers_the_projected_friction():
    v = np.linspace(0.02, 0.14, 7)
    full = _mu("ultrasonic", v, amp=1.6e-6)
    projected = _mu("ultrasonic_projected", v, amp=1.6e-6)
    assert np.all(projected < full) and np.all(projected > 0)


def test_vectorised_and_finite_over_prior_draws(rng):
    ds = skinfit.load_dataset("ultrasonic_synthetic")
    for name in ("ultrasonic", "ultrasonic_projected", "ultrasonic_constant_mu"):
        model, priors = skinfit.load_model(name), skinfit.load_priors(name)
        params = {p: priors[p].rvs(200, rng) for p in model.parameter_names}
        together = model.predict(params, ds.frame)
        assert together.shape == (200, len(ds)) and np.all(np.isfinite(together))
        for i in (0, 199):
            one = model.predict({p: v[i] for p, v in params.items()}, ds.frame)
            assert np.allclose(one, together[i], rtol=1e-13)


def test_make_regenerates_data_byte_for_byte(tmp_path):
    spec = importlib.util.spec_from_file_location("make_ultrasonic", DATA / "make.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(tmp_path / "data.csv")
    assert (tmp_path / "data.csv").read_bytes() == (DATA / "data.csv").read_bytes()


@pytest.mark.parametrize("column, value, match", [
    ("velocity", "-20", r"column 'velocity', row 5: expected a value > 0"),
    ("amplitude_pp", "-0.4", r"column 'amplitude_pp', row 5: expected a length >= 0"),
    ("direction_angle", "", r"column 'direction_angle', row 5: missing value"),
    ("frequency", "fast", r"column 'frequency', row 5: expected a number in kHz"),
    ("velocity", "nan", r"column 'velocity', row 5: missing value"),
    ("frequency", "0", r"column 'frequency', row 5: expected a value > 0"),
])
def test_bad_covariates_are_refused(tmp_path, column, value, match):
    d = tmp_path / "us"
    shutil.copytree(DATA, d)
    lines = (d / "data.csv").read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[5].split(",")
    cells[header.index(column)] = value
    lines[5] = ",".join(cells)
    (d / "data.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(skinfit.InputError, match=match):
        skinfit.load_dataset(d)


def _recovery(fit):
    truth = tomllib.loads((DATA / "dataset.toml").read_text())["provenance"]
    post = fit.idata["posterior"].to_dataset()
    checks = [(p, post[p].values, v) for p, v in truth["generating_parameters"].items()]
    checks.append(("sigma", post["sigma"].values, truth["noise"]["sigma"]))
    check_coverage(checks)


def test_recovery_without_vibration():
    """The paper's own fit: the no-vibration rows (42) determine all five parameters."""
    ds = skinfit.load_dataset("ultrasonic_synthetic")
    fit = skinfit.fit("ultrasonic", ds.subset(ds.frame["amplitude_pp"].to_numpy() == 0, "no vibration"), rng=1)
    assert fit.converged
    _recovery(fit)


@pytest.mark.slow
def test_recovery_on_the_shipped_dataset():
    fit = skinfit.fit("ultrasonic", "ultrasonic_synthetic", rng=1)
    assert fit.converged
    _recovery(fit)
