"""Ultrasonic friction models (Torres et al.; docs/models/ultrasonic.md): limits, the paper's peak, the
period quadrature's convergence, variants at zero amplitude, vectorisation, memory, finiteness
over the priors. The shipped dataset and recovery: tests/test_recovery_ultrasonic.py."""

import itertools
import math
import tracemalloc

import numpy as np
import pandas as pd
import pytest

import skinfit
from skinfit.physics import ultrasonic as us

PAPER = dict(mu_inf=1.86, mu_0=0.156, k_V=0.0048, q=0.0177, V0=0.068)  # Torres et al., Fig. 2 fit


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
    assert np.allclose(us._bracket(u, np.exp(-u)), direct.astype(float), rtol=1e-9)


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


def test_vibration_across_motion_lowers_the_projected_friction():
    v = np.linspace(0.02, 0.14, 7)
    full = _mu("ultrasonic", v, amp=1.6e-6)
    projected = _mu("ultrasonic_projected", v, amp=1.6e-6)
    assert np.all(projected < full) and np.all(projected > 0)


def test_vectorised_and_finite_over_prior_draws(rng):
    """k = 64 prior draws at once == 64 separate calls, all finite (no support refusals: the
    prior box lies inside mu_0 < 2*mu_inf), on the shipped rows."""
    ds = skinfit.load_dataset("ultrasonic_synthetic")
    for name in ("ultrasonic", "ultrasonic_projected", "ultrasonic_constant_mu"):
        model, priors = skinfit.load_model(name), skinfit.load_priors(name)
        params = {p: priors[p].rvs(64, rng) for p in model.parameter_names}
        together = model.predict(params, ds.frame)
        assert together.shape == (64, len(ds)) and np.all(np.isfinite(together))
        for i in range(64):
            one = model.predict({p: v[i] for p, v in params.items()}, ds.frame)
            assert np.allclose(one, together[i], rtol=1e-13)


def test_friction_factor_at_rest_at_its_speed_scale_and_fast():
    """Eq. 4 as printed, mu* = mu_inf + (mu_inf - mu_0)*exp(-V^2/k_V), in closed form with the
    paper's fit: 2*mu_inf - mu_0 = 3.564 at rest, mu_inf + (mu_inf - mu_0)/e at V = sqrt(k_V),
    mu_inf far above it; vectorised over an ensemble (k, 1) against speeds (n,)."""
    v = np.array([0.0, math.sqrt(PAPER["k_V"]), 10.0])
    got = us.mu_speed(v, PAPER["mu_inf"], PAPER["mu_0"], PAPER["k_V"])
    assert got == pytest.approx([3.564, 1.86 + 1.704 / math.e, 1.86], rel=1e-14)
    ens = us.mu_speed(v, np.array([[1.86], [1.0]]), np.array([[0.156], [0.5]]), PAPER["k_V"])
    assert ens.shape == (2, 3) and ens[1] == pytest.approx([1.5, 1.0 + 0.5 / math.e, 1.0], rel=1e-14)


def test_high_speed_limit():
    """Vs -> inf (cancellation in Vs*(1 - exp(-1/Vs)) - exp(-1/Vs)): eq. 3 evaluated directly in
    exact rational arithmetic with exp(-1/Vs) from its Taylor series to 30 terms agrees to 1e-12;
    mu_E -> mu*(q+1)/(q*Vs + 1) to leading order."""
    from fractions import Fraction

    q, v0 = Fraction(177, 10000), Fraction(68, 1000)
    for v in (1, 10, 1000, 10**5, 10**8):
        u = v0 / v
        e = sum((-u) ** j / math.factorial(j) for j in range(30))
        exact = 2 * (q + 1) * ((1 - e) / u - e) / (1 + q - e)
        got = us.mu_equilibrium(np.array(float(v)), 1.0, float(q), float(v0))
        assert got == pytest.approx(float(exact), rel=1e-12)
        assert got == pytest.approx(float((q + 1) / (q / u + 1)), rel=2 * float(u))


@pytest.mark.parametrize("angle", [0.0, 0.7, math.pi / 2, math.pi])
def test_projected_quadrature_converges(angle):
    v, amp = np.meshgrid(np.linspace(0.02, 0.14, 13), np.linspace(0, 1.6e-6, 9))
    x = {"velocity": v.ravel(), "direction_angle": np.full(v.size, angle), "amplitude_pp": amp.ravel(),
         "frequency": np.full(v.size, 58e3)}
    once = us.ultrasonic_projected(_p(), x, {})[0]["friction_coefficient"]
    ux, uy = math.cos(angle), math.sin(angle)

    def f(speed, vx, vy, rows):
        mu = us.mu_equilibrium(speed, us.mu_speed(speed, 1.86, 0.156, 0.0048), 0.0177, 0.068)
        return mu * (vx * ux + vy * uy) / speed

    twice = us.period_average(f, x["velocity"], x["direction_angle"], x["amplitude_pp"], x["frequency"],
                              m=2 * us.PHASES)
    assert np.max(np.abs(once - twice)) < 1e-6


@pytest.mark.parametrize("angle", [0.0, 0.7, math.pi / 2, math.pi, -math.pi / 2])
def test_zero_amplitude_reduces_all_three_variants(angle):
    """At A = 0 the relative velocity is the finger's own: (i) ``ultrasonic_projected`` equals
    ``ultrasonic`` (v_r . u_f / |v_r| = 1) at any angle; (ii) ``ultrasonic_constant_mu`` equals
    ``ultrasonic`` row by row with mu_plus = mu*(V_f) of eq. 4; (iii) the shortcut taken for
    A = 0 (no phase average) is the limit of the phase average as A -> 0+; (iv) none depends on
    the angle or the frequency."""
    v = np.linspace(0.02, 0.14, 7)
    full = _mu("ultrasonic", v, angle=angle)
    assert np.allclose(_mu("ultrasonic_projected", v, angle=angle), full, rtol=1e-12)
    star = us.mu_speed(v, PAPER["mu_inf"], PAPER["mu_0"], PAPER["k_V"])
    const = [_mu("ultrasonic_constant_mu", vi, angle=angle, mu_plus=si)[0] for vi, si in zip(v, star)]
    assert np.allclose(const, full, rtol=1e-12)
    for model in ("ultrasonic", "ultrasonic_projected", "ultrasonic_constant_mu"):
        assert np.allclose(_mu(model, v, angle=angle, amp=1e-15, mu_plus=1.5), _mu(model, v, angle=angle, mu_plus=1.5),
                           rtol=1e-9)
    assert np.allclose(full, _mu("ultrasonic", v, angle=0.3), rtol=1e-13)
    x = _x(v, angle=angle)
    x["frequency"] = np.full(v.size, 20e3)
    assert np.allclose(us.ultrasonic(_p(), x, {})[0]["friction_coefficient"][0], full, rtol=1e-13)


def test_memory_stays_within_a_few_phase_arrays():
    """k = 64 parameter vectors x n = 500 rows x 2*PHASES phases: peak allocation below eight
    (k, n, 2*PHASES) float64 arrays (measured: about six)."""
    rng = np.random.default_rng(0)
    n, k = 500, 64
    x = {"velocity": rng.uniform(0.02, 0.14, n), "direction_angle": rng.choice([0.0, math.pi / 2], n),
         "amplitude_pp": rng.uniform(0.1e-6, 1.6e-6, n), "frequency": np.full(n, 58e3)}
    p = {name: np.full((k, 1), value) for name, value in PAPER.items()}
    one_array = k * n * 2 * us.PHASES * 8
    for f in (us.ultrasonic, us.ultrasonic_projected):
        tracemalloc.start()
        try:
            y = f(p, x, {})[0]["friction_coefficient"]
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert y.shape == (k, n) and peak < 8 * one_array, peak / one_array


@pytest.mark.parametrize("name", ["ultrasonic", "ultrasonic_projected", "ultrasonic_constant_mu"])
def test_finite_at_every_corner_of_the_prior_bounds(name):
    """All 2**d corners of the prior box, on the shipped rows plus extreme speeds/angles."""
    model, priors = skinfit.load_model(name), skinfit.load_priors(name)
    corners = np.array(list(itertools.product(*((priors[p].lower, priors[p].upper) for p in model.parameter_names))))
    params = {p: corners[:, i] for i, p in enumerate(model.parameter_names)}
    frame = skinfit.load_dataset("ultrasonic_synthetic").frame.copy()
    extra = frame.iloc[:4].copy()
    extra["velocity"] = [1e-9, 1e-9, 10.0, 10.0]
    extra["direction_angle"] = [0.0, 1e-3, 0.0, math.pi / 2]
    extra["amplitude_pp"] = [1.6e-6, 1.6e-6, 10e-6, 0.0]
    y, valid = model.predict(params, pd.concat([frame, extra], ignore_index=True), return_valid=True)
    assert y.shape == (2 ** len(model.parameter_names), len(frame) + 4)
    assert valid.all() and np.all(np.isfinite(y))  # the prior box lies inside the support
    if name != "ultrasonic_projected":  # a mean of mu_E >= 0 (the projection may be negative)
        assert np.all(y >= 0)


@pytest.mark.parametrize("name", ["ultrasonic", "ultrasonic_projected"])
def test_support_is_a_positive_friction_factor(name):
    """mu* of eq. 4 runs from 2*mu_inf - mu_0 (at rest) to mu_inf: negative at low speed when
    mu_0 > 2*mu_inf, which the model refuses (ok = False) instead of predicting negative friction."""
    p = {**_p(), "mu_inf": np.array([[1.0], [1.0]]), "mu_0": np.array([[1.9], [2.1]])}
    y, ok = getattr(us, name)(p, _x([0.02, 0.14], amp=1.6e-6), {})
    assert np.array_equal(np.broadcast_to(ok, (2, 2)), [[True, True], [False, False]])
    assert np.all(np.isfinite(y["friction_coefficient"]))


def _reference_average(name, p, x):
    """Model ``name``'s friction by :func:`period_average` of :func:`mu_equilibrium` on
    (k, rows, nodes) arrays, parameters ``p`` (k, 1) or (k, n): the reference the models' own
    averages (flat nodes, interpolation) are tested against."""
    e = {k: np.asarray(v, dtype=float)[..., None] for k, v in p.items()}
    ux, uy = np.cos(x["direction_angle"]), np.sin(x["direction_angle"])

    def per_row(k, rows):
        return e[k][:, rows] if e[k].shape[1] > 1 else e[k]

    def integrand(speed, vx, vy, rows):
        star = (per_row("mu_plus", rows) if name == "ultrasonic_constant_mu"
                else us.mu_speed(speed, per_row("mu_inf", rows), per_row("mu_0", rows), per_row("k_V", rows)))
        mu = us.mu_equilibrium(speed, star, per_row("q", rows), per_row("V0", rows))
        if name == "ultrasonic_projected":
            with np.errstate(invalid="ignore", divide="ignore"):
                mu = mu * np.where(speed > 0, (vx * ux[rows, None] + vy * uy[rows, None]) / speed, 0.0)
        return mu

    return us.period_average(integrand, *us._rows(x))


@pytest.mark.parametrize("block_cells", [10**9, 500])
def test_flat_blocked_average_equals_the_reference_quadrature(block_cells, monkeypatch, rng):
    """The models' period average (nodes of all rows on one axis, cached, parameter vectors in
    blocks) equals period_average of mu_equilibrium on (k, rows, nodes) arrays, for the three
    variants; parameters shared (k, 1), per row (k, n) (a split parameter) and single (1, 1)
    mixed; rows at rest, without vibration, along and across the vibration axis."""
    monkeypatch.setattr(us, "BLOCK_CELLS", block_cells)
    n, k = 40, 7
    x = {"velocity": rng.uniform(0.0, 0.14, n), "direction_angle": rng.choice([0.0, 0.01, 0.7, math.pi / 2, math.pi], n),
         "amplitude_pp": rng.choice([0.0, 0.4e-6, 1.6e-6], n), "frequency": np.full(n, 58e3)}
    x["velocity"][:3], x["amplitude_pp"][:3], x["amplitude_pp"][3:6] = 0.0, 0.0, 1.6e-6
    p = {"mu_inf": rng.uniform(1.0, 3.0, (k, 1)), "mu_0": rng.uniform(0.01, 0.9, (k, n)), "k_V": np.array([[0.0048]]),
         "q": rng.uniform(0.001, 0.1, (k, 1)), "V0": rng.uniform(0.02, 0.2, (k, 1)), "mu_plus": rng.uniform(1.0, 2.0, (k, n))}
    for name in ("ultrasonic", "ultrasonic_projected", "ultrasonic_constant_mu"):
        want = _reference_average(name, p, x)
        got = getattr(us, name)(p, x, {})[0]["friction_coefficient"]
        assert got.shape == (k, n) and np.all(np.isfinite(got))
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
        assert np.all(got[:, :3] == 0.0)  # a finger at rest on a plate at rest: mu_E(0) = 0
        assert np.all(got[:, 3:6] != 0.0)


def _design_with_extremes():
    """The shipped rows plus rows at 1e-9 and 10 m/s, along, near and across the vibration axis."""
    frame = skinfit.load_dataset("ultrasonic_synthetic").frame.copy()
    extra = frame.iloc[:6].copy()
    extra["velocity"] = [1e-9, 1e-9, 10.0, 10.0, 0.05, 0.05]
    extra["direction_angle"] = [0.0, 1e-3, 0.0, math.pi / 2, 0.01, 0.0]
    extra["amplitude_pp"] = [1.6e-6, 1.6e-6, 10e-6, 0.0, 1.6e-6, 1.6e-6]
    return _covariates(pd.concat([frame, extra], ignore_index=True))


def _covariates(frame):
    return {c: frame[c].to_numpy(float) for c in ("velocity", "direction_angle", "amplitude_pp", "frequency")}


def _node_sums(p, x):
    """us.ultrasonic's friction summed over the quadrature nodes (no interpolation): ``q``
    given per row, as a parameter split by a column would be (on two rows or more: one row's
    (k, 1) reads as shared)."""
    assert len(x["velocity"]) > 1
    per_row = {**p, "q": np.broadcast_to(p["q"], (len(p["q"]), len(x["velocity"])))}
    return us.ultrasonic(per_row, x, {})[0]["friction_coefficient"]


@pytest.mark.parametrize("name", ["ultrasonic", "ultrasonic_projected", "ultrasonic_constant_mu"])
def test_interpolated_average_equals_the_reference_quadrature(name, rng):
    """With parameters shared by all rows the models interpolate mu in log speed
    (_interpolation); over 400 prior draws the averages equal period_average of
    mu_equilibrium on the same Gauss-Legendre nodes (the reference, computed independently on
    (k, rows, nodes) arrays) within 1e-10, on the shipped rows plus extreme ones (6.2 decades
    of node speeds)."""
    model, priors = skinfit.load_model(name), skinfit.load_priors(name)
    x = _design_with_extremes()
    theta = {p: priors[p].rvs((400, 1), rng) for p in model.parameter_names}
    want = _reference_average(name, theta, x)
    got = getattr(us, name)(theta, x, {})[0]["friction_coefficient"]
    assert got.shape == want.shape == (400, len(x["velocity"]))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-10)


def test_interpolation_points_scale_with_the_decades_of_node_speeds(monkeypatch, rng):
    """The number of interpolation points follows the span of node speeds (192 on the shipped
    rows, 4.8 decades; more with the extreme rows), and too few per decade show: at 7 per decade
    the averages miss the reference by > 1e-4 (the accuracy test above can fail)."""
    frame = skinfit.load_dataset("ultrasonic_synthetic").frame
    shipped = _covariates(frame)
    n_shipped = us._interpolation(*us._rows(shipped), scalars=(us.PHASES, False))[2].shape[1]
    n_extreme = us._interpolation(*us._rows(_design_with_extremes()), scalars=(us.PHASES, False))[2].shape[1]
    assert n_shipped == 192 and n_extreme > n_shipped
    theta = {p: np.full((1, 1), v) for p, v in PAPER.items()}
    theta.update(k_V=rng.uniform(1e-5, 1e-2, (200, 1)), V0=rng.uniform(1e-3, 0.3, (200, 1)))
    want = _node_sums(theta, shipped)
    assert np.abs(us.ultrasonic(theta, shipped, {})[0]["friction_coefficient"] - want).max() < 1e-11
    monkeypatch.setattr(us, "INTERP_PER_DECADE", 7)
    us._interpolation.cache_clear()
    try:
        assert np.abs(us.ultrasonic(theta, shipped, {})[0]["friction_coefficient"] - want).max() > 1e-4
    finally:
        us._interpolation.cache_clear()


@pytest.mark.parametrize("velocity, amp", [([0.08, 0.08], 0.0), ([0.0, 0.0], 0.0), ([0.0, 0.05], 0.0), ([], 0.0)],
                         ids=["one speed", "all at rest", "one at rest", "no rows"])
def test_interpolation_of_degenerate_designs(velocity, amp):
    """Designs whose node speeds span no interval: a single speed (one interpolation point),
    only fingers at rest (nothing to interpolate: 0), none at all; equal to the node sums, and
    without vibration to eqs. 3-4 written out (mu_E at the finger's own speed)."""
    x = _x(velocity, amp=amp)
    p = {k: np.array([[v], [2 * v]]) for k, v in PAPER.items()}
    got = us.ultrasonic(p, x, {})[0]["friction_coefficient"]
    want = _node_sums(p, x) if velocity else np.empty((2, 0))
    assert got.shape == (2, len(velocity)) and np.all(np.isfinite(got))
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=0)
    if velocity:
        assert np.all((got == 0) == (np.asarray(velocity) == 0))  # mu_E(0) = 0
    for j, v in enumerate(velocity):
        if v > 0:
            a = {k: w[:, 0] for k, w in p.items()}
            e = np.exp(-a["V0"] / v)
            star = a["mu_inf"] + (a["mu_inf"] - a["mu_0"]) * np.exp(-v * v / a["k_V"])
            want_j = 2 * star * (a["q"] + 1) * (v / a["V0"] * (1 - e) - e) / (1 + a["q"] - e)
            np.testing.assert_allclose(got[:, j], want_j, rtol=1e-13)


def test_q_slope_of_log_mu_behind_the_mu_inf_shear():
    """The reason models/ultrasonic.toml samples log(mu_inf / (1 + q)) (mu_inf_offset): at
    q -> 0, d log mu_E / dq = 1 - 1/(1 - E) = -1/(exp(V0/V) - 1), E = exp(-V0/V) (eq. 3
    differentiated by hand), about -1 at V ~ 1.5 V0 and log(1 + q) ~ q there.  Central
    differences of mu_equilibrium at q = 1e-4 +- 1e-6 against the closed form."""
    v0, h, q = 0.068, 1e-6, 1e-4
    v = v0 * np.array([0.3, 1.0, 1.5, 2.0])
    slope = (np.log(us.mu_equilibrium(v, 1.8, q + h, v0)) - np.log(us.mu_equilibrium(v, 1.8, q - h, v0))) / (2 * h)
    closed = -1.0 / np.expm1(v0 / v)
    np.testing.assert_allclose(slope, closed, rtol=1e-3)
    assert closed[2] == pytest.approx(-1.0, abs=0.06)
