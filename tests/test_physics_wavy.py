"""Wavy-surface models (Fujii, Okamoto & Yamada; docs/models/wavy_surface.md): closed forms, the paper's Section 5
claims, support, vectorisation, the shipped dataset and recovery."""

import importlib.util
import shutil
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest
from recovery import check_coverage

import skinfit
from skinfit.physics.wavy import ball_bearing_ratio, slope, two_point_ratio

ROOT = Path(skinfit.__file__).resolve().parents[1]
DATA = ROOT / "datasets" / "wavy_synthetic"
PAPER = dict(R=7e-3, r=3.4e-3, s=6e-3, mu=0.4, n=-0.3)  # Fujii, Okamoto & Yamada, Section 6.1
LAM, A = 0.04, 1.5e-3
X = np.linspace(0.0, LAM, 4001)[:-1]


def _ratio(direction=1, fy=1.0, **kw):
    p = {**PAPER, **kw}
    return two_point_ratio(X, A, LAM, direction, fy, p["R"], p["r"], p["s"], p["mu"], p["n"])


def test_ball_bearing_ratio_is_the_surface_slope():
    y = lambda x: A * np.cos(2 * np.pi * x / LAM)  # noqa: E731 - the surface of eq. 1
    h = 1e-7
    numeric = (y(X + h) - y(X - h)) / (2 * h)
    assert np.allclose(ball_bearing_ratio(X, A, LAM), numeric, atol=1e-8)


@pytest.mark.parametrize("direction", [1, -1])
@pytest.mark.parametrize("n", [-0.3, 0.0, 0.3])
def test_two_point_without_spread_or_friction_is_the_ball_bearing(direction, n):
    ratio, ok = _ratio(direction, r=0.0, mu=0.0, n=n)
    assert ok.all()
    assert np.allclose(ratio, slope(X, A, LAM), atol=1e-15)


def _phases(ratio):
    """Lengths of the rising (trough -> next peak, along +x) and falling phases."""
    lo, hi = X[np.argmin(ratio)], X[np.argmax(ratio)]
    rising = (hi - lo) % LAM
    return rising, LAM - rising


def test_skewed_rising_phase_shorter_for_rightward_sliding():
    rising, falling = _phases(_ratio(1)[0])
    assert rising < 0.95 * falling          # Section 5.1: rises rapidly, falls slowly
    bb_rising, bb_falling = _phases(slope(X, A, LAM))
    assert bb_rising == pytest.approx(bb_falling, abs=2 * (X[1] - X[0]))  # symmetric without contact spread
    r_small, f_small = _phases(_ratio(1, r=1.5e-3)[0])  # Fig. 10: larger r, more skew
    assert rising / falling < r_small / f_small < 1.0


def test_direction_flips_the_base_shift_and_load_lowers_it():
    up, down = _ratio(1)[0].mean(), _ratio(-1)[0].mean()
    assert up > 0.2 and down < -0.2 and up == pytest.approx(-down)  # slope averages to 0
    light, heavy = _ratio(1, fy=0.9)[0].mean(), _ratio(1, fy=2.4)[0].mean()
    assert heavy < light                    # n < 0: larger load, smaller ratio (Section 6.2)
    assert _ratio(1, fy=2.4, n=0.0)[0].mean() == pytest.approx(_ratio(1, fy=0.9, n=0.0)[0].mean())


def test_leftward_sliding_is_the_mirror_image():
    """The surface is even in x: reflecting x -> -x turns leftward sliding into rightward sliding
    and flips the sign of the horizontal force, so ratio(x, -1) = -ratio(-x, +1)."""
    left, ok_left = _ratio(-1)
    mirror = two_point_ratio(-X, A, LAM, 1, 1.0, *(PAPER[k] for k in ("R", "r", "s", "mu", "n")))[0]
    assert ok_left.all()
    assert np.allclose(left, -mirror, atol=1e-13)


def test_an_unloaded_point_contributes_nothing():
    """On the steep flank only the uphill point lies under the shifted pressure profile: the ratio
    is that one ball's, (g + mu*f**n)/(1 - mu*f**n*g) with the whole load f = f_y (eqs. 9, 11),
    even for n < 0, where the unloaded point's mu*0**n would be infinite."""
    a, lam, fy = 2.5e-3, 0.02, 1.3
    R, r, s, mu, n = 7e-3, 3e-3, 2e-3, 0.4, -0.3
    x = np.array([-lam / 4, lam / 4])           # steepest up- and down-slope
    with warnings.catch_warnings():
        warnings.simplefilter("error")           # no 0*inf, no division warnings
        ratio, ok = two_point_ratio(x, a, lam, 1, fy, R, r, s, mu, n)
    g_up = slope(x + np.array([r, -r]), a, lam)  # the loaded point is the uphill one
    m = mu * fy**n
    assert ok.all()
    assert np.allclose(ratio, (g_up + m) / (1 - m * g_up), rtol=1e-12)


def test_support_limits():
    # |shift| <= R*sin(arctan(2*pi*a/lambda)) = 1.6 mm, so |+-r - shift| >= 1.8 mm > s: no point loaded
    _, ok = _ratio(1, s=0.5e-3, r=3.4e-3)
    assert not ok.any()
    # light load, sticky skin: mu_pm >= 1.5*0.05**-0.5 = 6.7, so the cone locks where a loaded
    # point climbs a slope > 0.15; where both points go downhill (g <= 0) 1 - mu_pm*g >= 1
    a, lam, r = 2.5e-3, 0.02, 3.4e-3
    _, ok = two_point_ratio(X, a, lam, 1, 0.05, 7e-3, r, 6e-3, 1.5, -0.5)
    downhill = (slope(X + r, a, lam) <= 0) & (slope(X - r, a, lam) <= 0)
    assert ok[downhill].all() and not ok.all()
    assert not ok[np.argmax(slope(X, a, lam))]  # steepest climb: the loaded point climbs 0.38
    ratio, ok = _ratio(1)
    assert ok.all() and np.all(np.isfinite(ratio))


@pytest.mark.parametrize("name", ["wavy_surface", "wavy_two_point_coulomb"])
def test_vectorised_over_parameter_ensembles(rng, name):
    """64 prior draws at once give what 64 separate calls give (NaN where outside the support)."""
    model, priors = skinfit.load_model(name), skinfit.load_priors(name)
    ds = skinfit.load_dataset("wavy_synthetic")
    params = {p: priors[p].rvs(64, rng) for p in model.parameter_names}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.SupportWarning)
        together = model.predict(params, ds.frame)
        assert together.shape == (64, len(ds)) and np.isfinite(together).mean() > 0.9
        for i in range(64):
            one = model.predict({p: v[i] for p, v in params.items()}, ds.frame)
            assert np.allclose(one.ravel(), together[i], rtol=1e-12, atol=1e-15, equal_nan=True)


def test_variants():
    ds = skinfit.load_dataset("wavy_synthetic")
    bb = skinfit.load_model("wavy_ball_bearing").predict({}, ds.frame).ravel()
    f = ds.frame
    assert np.allclose(bb, slope(f["position"], f["amplitude"], f["wavelength"]))
    coulomb = skinfit.load_model("wavy_two_point_coulomb")
    full = skinfit.load_model("wavy_surface")
    p = {k: v for k, v in PAPER.items() if k != "n"}
    a = coulomb.predict(p, f)
    b = full.predict({**p, "n": 0.0}, f)
    assert np.allclose(a, b)


# ---- the shipped dataset ----------------------------------------------------------------

def test_make_regenerates_data_byte_for_byte(tmp_path):
    spec = importlib.util.spec_from_file_location("make_wavy", DATA / "make.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(tmp_path / "data.csv")
    assert (tmp_path / "data.csv").read_bytes() == (DATA / "data.csv").read_bytes()


@pytest.mark.parametrize("column, value, match", [
    ("direction", "0", r"column 'direction', row 4: expected one of -1, 1 \(got '0'\)"),
    ("wavelength", "-20", r"column 'wavelength', row 4: expected a length >= 0"),
    ("wavelength", "0", r"column 'wavelength', row 4: expected a value > 0"),
    ("amplitude", "", r"column 'amplitude', row 4: missing value"),
    ("normal_force", "-1", r"column 'normal_force', row 4: expected a force >= 0"),
    ("direction", "NaN", r"column 'direction', row 4: missing value"),
    ("amplitude", "-0.5", r"column 'amplitude', row 4: expected a length >= 0"),
    ("position", "inf", r"column 'position', row 4: expected a finite number"),
])
def test_bad_covariates_are_refused(tmp_path, column, value, match):
    d = tmp_path / "wavy"
    shutil.copytree(DATA, d)
    lines = (d / "data.csv").read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[4].split(",")
    cells[header.index(column)] = value
    lines[4] = ",".join(cells)
    (d / "data.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(skinfit.InputError, match=match):
        skinfit.load_dataset(d)


def test_recovery_on_the_shipped_dataset():
    truth = tomllib.loads((DATA / "dataset.toml").read_text())["provenance"]["generating_parameters"]
    fit = skinfit.fit("wavy_surface", "wavy_synthetic", rng=1, split={"r": "wavelength", "s": "wavelength"})
    assert fit.converged
    post = fit.idata["posterior"].to_dataset()
    checks = [(p, post[p].values, truth[p]) for p in ("R", "mu", "n")]
    checks.append(("sigma", post["sigma"].values, 0.05))
    for p in ("r", "s"):
        dim = [d for d in post[p].dims if d not in ("chain", "draw")][0]
        for level in post[p][dim].values:
            key = f"{float(level) * 1e3:g}" if float(level) < 1 else f"{float(level):g}"
            checks.append((f"{p}[{level}]", post[p].sel({dim: level}).values, truth[p][key]))
    assert len(checks) == 12
    check_coverage(checks)
