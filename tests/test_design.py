"""Experimental design (skinfit.design): estimators against closed forms, known optimal
designs, the command line and its errors."""

import itertools

import numpy as np
import pandas as pd
import pytest

import skinfit
from skinfit.cli import main
from skinfit.design import (batch_eig, discrimination_plan, eig_nmc, gaussian_problem, greedy_plan,
                            laplace_design, read_candidates)
from skinfit.errors import InputError

SIGMA = 0.5
COV = np.array([[1.0, 0.3, 0.0], [0.3, 2.0, 0.5], [0.0, 0.5, 0.7]])


def _linear(cov, sigma=SIGMA, rng=None, n_draws=20000):
    """y = x . u + N(0, sigma^2), u ~ N(0, cov): EIG(X) = 0.5 log det(I + X cov X^T / sigma^2)."""
    d = len(cov)
    names = [f"u{j}" for j in range(d)]

    def mean(u, X):
        return sum(u[:, j:j + 1] * X[f"x{j}"][None] for j in range(d))[..., None]

    draws = rng.multivariate_normal(np.zeros(d), cov, n_draws)
    return gaussian_problem(names, mean, sigma, np.zeros(d), cov, draws)


def _closed_form(rows, cov, sigma=SIGMA, focus=None):
    S = np.linalg.inv(np.linalg.inv(cov) + rows.T @ rows / sigma**2)
    f = np.arange(len(cov)) if focus is None else np.asarray(focus)
    return 0.5 * (np.linalg.slogdet(cov[np.ix_(f, f)])[1] - np.linalg.slogdet(S[np.ix_(f, f)])[1]), S


def test_nested_mc_eig_of_one_measurement_matches_linear_gaussian_closed_form(rng):
    problem = _linear(COV, rng=rng)
    rows = rng.normal(size=(6, 3))
    X = {f"x{j}": rows[:, j] for j in range(3)}
    exact = np.array([_closed_form(r[None], COV)[0] for r in rows])
    got = eig_nmc(problem, X, rng, n_outer=1500, n_inner=1500)
    for key in ("eig", "eig_upper"):  # the estimate (outer draw included) and the upper bound (Ryan 2003)
        eig, se = got[key], got[key + "_se"]
        assert np.all(np.abs(eig - exact) < 4 * se + np.abs(got["eig_bias"])), (key, eig, exact, se)
        assert np.all(se < 0.03)


def test_nested_mc_eig_of_a_subset_matches_closed_form_with_independent_prior(rng):
    cov = np.diag([1.0, 2.0, 0.7])
    problem = _linear(cov, rng=rng)
    rows = rng.normal(size=(4, 3))
    X = {f"x{j}": rows[:, j] for j in range(3)}
    exact = np.array([_closed_form(r[None], cov, focus=[0, 1])[0] for r in rows])
    got = eig_nmc(problem, X, rng, params=["u0", "u1"], n_outer=800, n_inner=800)
    assert np.all(np.abs(got["eig"] - exact) < 4 * got["eig_se"] + np.abs(got["eig_bias"])), (got, exact)


@pytest.mark.parametrize("idx,focus", [([0, 1, 2, 3, 3], None), ([1, 1, 1], None), ([0, 2, 4, 5], [0, 1]),
                                       ([3, 4], [2])])
def test_batch_eig_matches_linear_gaussian_closed_form(rng, idx, focus):
    problem = _linear(COV, rng=rng)
    rows = rng.normal(size=(6, 3))[idx]
    X = {f"x{j}": rows[:, j] for j in range(3)}
    params = None if focus is None else [f"u{j}" for j in focus]
    exact, S = _closed_form(rows, COV, focus=focus)
    eig, se, bias = batch_eig(problem, X, rng, params=params, n_outer=300, n_inner=200)
    assert abs(eig - exact) < 4 * se + abs(bias), (eig, exact, se, bias)
    lap, sd = laplace_design(problem, X, problem.draws[:20], params)  # exact for a linear model
    assert lap == pytest.approx(exact, rel=1e-6)
    assert sd == pytest.approx(np.sqrt(np.diag(S)), rel=1e-6)


def _brute_force(rows, cov, n, sigma=SIGMA):
    best, plan = -np.inf, None
    for combo in itertools.combinations_with_replacement(range(len(rows)), n):
        value = _closed_form(rows[list(combo)], cov, sigma)[0]
        if value > best + 1e-12:
            best, plan = value, combo
    return sorted(plan), best


@pytest.mark.parametrize("degree,n", [(1, 4), (2, 3), (2, 6)])
def test_greedy_plan_equals_brute_force_d_optimal_polynomial_regression(rng, degree, n):
    """Polynomial regression on x in [-1, 1] (9 candidates), prior N(0, I): the D-optimal
    plans are known (ends for a line; -1, 0, 1 for a quadratic) and found by brute force."""
    x = np.linspace(-1, 1, 9)
    rows = np.column_stack([x**k for k in range(degree + 1)])
    cov = np.eye(degree + 1)
    problem = _linear(cov, sigma=0.3, rng=rng, n_draws=200)
    X = {f"x{j}": rows[:, j] for j in range(degree + 1)}
    idx, gains, _, _ = greedy_plan(problem, X, n, rng, n_outer=10)
    plan, best = _brute_force(rows, cov, n, sigma=0.3)
    assert sorted(idx) == plan
    assert gains.sum() == pytest.approx(best, rel=1e-6)  # Laplace gains telescope to the batch EIG
    assert set(x[plan]) == ({-1.0, 1.0} if degree == 1 else {-1.0, 0.0, 1.0})


def test_contact_area_power_law_plan_at_both_ends_of_the_force_range():
    """log A = log alpha_a + m log F: information about (alpha_a, m) is maximal at the ends of
    the force range, half the measurements at each."""
    cands = {"grid": {"normal_force": {"unit": "N", "from": 0.1, "to": 5.0, "num": 12, "log": True},
                      "actuation_force": {"unit": "N", "values": [0.0]}}}
    result = skinfit.design("contact_area", cands, n=12, params=["alpha_a0", "m0"], rng=3, n_outer=100,
                            n_inner=100)
    forces = result.plan["normal_force [N]"].to_numpy()
    assert set(np.round(forces, 9)) == {0.1, 5.0}
    assert 4 <= np.sum(forces == 0.1) <= 8
    assert result.table["eig_laplace"].idxmax() in (0, 11)  # one measurement: an end too


def test_discrimination_plan_measures_where_the_models_differ(rng):
    """Model A: y = u (x-independent); model B: y = u x.  At x = 1 they predict alike; at x = 0
    B predicts y = 0 exactly, A anything: the one-point plan measures at x = 0."""
    x = np.array([1.0, 0.5, 0.0])
    draws = rng.normal(size=(4000, 1))
    a = gaussian_problem(["u"], lambda u, X: (u * np.ones_like(X["x"])[None])[..., None], 0.1, [0.0], [[1.0]], draws)
    b = gaussian_problem(["u"], lambda u, X: (u * X["x"][None])[..., None], 0.1, [0.0], [[1.0]], draws)
    idx, table = discrimination_plan([a, b], {"x": x}, 1, rng, n_outer=300, n_inner=500)
    assert idx.tolist() == [2]
    _, same = discrimination_plan([a, b], {"x": x}, 1, rng, n_outer=300, n_inner=500, plan=[0])
    assert table["expected_ln_bf_capped"].min() > 0.5 and abs(same["expected_ln_bf_capped"]).max() < 0.05


def test_design_from_a_fit_uses_its_posterior_and_noise(ea_fit):
    cands = {"grid": {"normal_force": {"unit": "mN", "from": 200, "to": 2000, "num": 4},
                      "voltage": {"unit": "V", "values": [0, 200]}}}
    result = skinfit.design(ea_fit, cands, n=6, params=["alpha", "eta"], rng=1, n_outer=100, n_inner=100)
    sigma = np.median(ea_fit.group("posterior")["sigma"].values)
    assert result.settings["noise"]["tangential_force"]["scale"] == pytest.approx(sigma)
    assert "posterior of fit electroadhesion" in result.settings["start"]
    assert len(result.plan) == 6 and list(result.sd.index) == ["alpha", "eta"]
    # the fit's posterior sd of log(eta) in the coordinate of the design
    log_eta = np.log(ea_fit.group("posterior")["eta"].values.ravel())
    assert result.sd.loc["eta", "now"] == pytest.approx(log_eta.std(), rel=0.1)
    assert (result.sd["plan"] <= result.sd["now"]).all()


def _grid(tmp_path, text):
    path = tmp_path / "grid.toml"
    path.write_text(text)
    return str(path)


GRID = """
[grid.normal_force]
unit = "mN"
values = [200, 600, 1000, 2000]
[grid.voltage]
unit = "V"
values = [0, 100, 200]
"""


def test_cli_writes_plan_csv_in_user_units(tmp_path, capsys):
    out = tmp_path / "d"
    code = main(["design", "electroadhesion", "--candidates", _grid(tmp_path, GRID), "--n", "5", "--outer", "60",
                 "--inner", "60", "--sigma", "0.02", "--seed", "4", "--out", str(out)])
    assert code == 0
    plan = pd.read_csv(out / "plan.csv")
    assert list(plan.columns[:3]) == ["order", "normal_force [mN]", "voltage [V]"] and len(plan) == 5
    assert set(plan["normal_force [mN]"]) <= {200, 600, 1000, 2000}
    assert set(plan["voltage [V]"]) <= {0, 100, 200}
    assert (out / "eig.png").exists() and len(pd.read_csv(out / "candidates.csv")) == 12
    assert "plan vs baseline" in capsys.readouterr().out


@pytest.mark.parametrize("argv,message", [
    (["--candidates", "GRID_BAD_COV"], "unknown covariate 'speed'"),
    (["--candidates", "GRID", "--params", "E_star,nope"], "unknown parameter 'nope'"),
    (["--candidates", "GRID", "--n", "0"], "must be > 0"),
    (["--candidates", "GRID_BAD_UNIT"], "unit 'mm' is a length"),
    (["--candidates", "GRID_NEGATIVE"], "normal_force must be >= 0"),
])
def test_cli_bad_input_one_line_error_exit_2(tmp_path, capsys, argv, message):
    files = {"GRID": GRID, "GRID_BAD_COV": GRID + '[grid.speed]\nunit = "mm/s"\nvalues = [1]\n',
             "GRID_BAD_UNIT": GRID.replace('unit = "mN"', 'unit = "mm"'),
             "GRID_NEGATIVE": GRID.replace("200, 600", "-200, 600")}
    argv = [_grid(tmp_path, files[a]) if a in files else a for a in argv]
    assert main(["design", "electroadhesion", "--outer", "20", "--inner", "20", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and err.count("\n") == 0 and "Traceback" not in err


def test_candidates_as_a_list_of_points_convert_to_si():
    model = skinfit.load_model("electroadhesion")
    X, units = read_candidates({"units": {"normal_force": "mN", "voltage": "kV"},
                                "points": [{"normal_force": 500, "voltage": 0.1},
                                           {"normal_force": 1500, "voltage": 0.2}]}, model)
    assert X["normal_force"].tolist() == [0.5, 1.5] and X["voltage"].tolist() == [100.0, 200.0]
    with pytest.raises(InputError, match="row 2: covariate 'voltage' missing"):
        read_candidates({"units": {"normal_force": "mN", "voltage": "V"},
                         "points": [{"normal_force": 500, "voltage": 0}, {"normal_force": 1500}]}, model)
    with pytest.raises(InputError, match="no candidate values for covariate.*voltage"):
        read_candidates({"grid": {"normal_force": {"unit": "N", "values": [1.0]}}}, model)


def test_same_seed_same_plan():
    cands = {"grid": {"normal_force": {"unit": "N", "values": [0.2, 1.0, 2.0]}, "voltage": {"unit": "V",
                                                                                          "values": [0, 200]}}}
    a = skinfit.design("electroadhesion", cands, n=4, rng=7, n_outer=50, n_inner=50, noise_scale=0.02)
    b = skinfit.design("electroadhesion", cands, n=4, rng=7, n_outer=50, n_inner=50, noise_scale=0.02)
    pd.testing.assert_frame_equal(a.table, b.table)
    pd.testing.assert_frame_equal(a.comparison, b.comparison)
    assert a.settings["seed"] == 7


def test_report_section_shows_plan_comparison_and_figure(tmp_path):
    from skinfit.design import design_section_html

    cands = {"grid": {"normal_force": {"unit": "N", "values": [0.2, 1.0, 2.0]}, "voltage": {"unit": "V",
                                                                                          "values": [0, 200]}}}
    result = skinfit.design("electroadhesion", cands, n=3, rng=2, n_outer=40, n_inner=40, noise_scale=0.02)
    html = design_section_html(result, tmp_path / "figures")
    assert (tmp_path / "figures" / "design_electroadhesion.png").stat().st_size > 1000
    assert 'src="figures/design_electroadhesion.png"' in html
    assert html.count("<table") == 3 and "Plan vs baseline" in html


def test_skinfit_report_shows_a_design_folder_as_a_section(tmp_path, capsys):
    """`skinfit design --out D` then `skinfit report RUN D --out R`: the design written to disk
    comes back equal (load_design) and the report carries its section, figure and plan."""
    import re

    from skinfit.cli import main
    from skinfit.design import load_design

    cands = {"grid": {"normal_force": {"unit": "N", "values": [0.2, 1.0, 2.0]}, "voltage": {"unit": "V",
                                                                                          "values": [0, 200]}}}
    result = skinfit.design("electroadhesion", cands, n=3, rng=2, n_outer=40, n_inner=40, noise_scale=0.02)
    back = load_design(result.write(tmp_path / "design"))
    pd.testing.assert_frame_equal(back.plan, result.plan.reset_index(drop=True), check_dtype=False)
    assert back.model_id == "electroadhesion" and back.settings["seed"] == 2
    assert main(["fit", "electroadhesion_coulomb", "electroadhesion_synthetic", "--out", str(tmp_path / "run"),
                 "--seed", "1", "--quiet"]) in (0, 3)
    assert main(["report", str(tmp_path / "run"), str(tmp_path / "design"), "--out", str(tmp_path / "rep")]) == 0
    page = (tmp_path / "rep" / "index.html").read_text()
    assert 'href="#design-electroadhesion"' in page and "Design the next experiment: electroadhesion" in page
    assert (tmp_path / "rep" / "figures" / "design_electroadhesion.png").stat().st_size > 1000
    plan_rows = re.search(r"<h3>Plan \(user units\)</h3>(.*?)</table>", page, re.S).group(1).count("<tr")
    assert plan_rows == 1 + len(result.plan)  # header + the plan's rows
    with pytest.raises(skinfit.InputError, match="not a folder written by `skinfit design --out`"):
        load_design(tmp_path / "run")


def test_candidates_file_read_as_a_card_is(tmp_path):
    """A candidates file goes through the card reader: a FIFO is refused before reading (it would
    wait for ever), bad TOML names the file and its line."""
    import os

    from skinfit.design import read_candidates

    model = skinfit.load_model("electroadhesion")
    fifo = tmp_path / "grid.toml"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="FIFO"):
        read_candidates(str(fifo), model)
    bad = tmp_path / "bad.toml"
    bad.write_text("[grid.normal_force\nunit = 'N'\n")
    with pytest.raises(InputError, match="bad.toml"):
        read_candidates(str(bad), model)


# ---- design from a fit: a linear-Gaussian model fitted to data, its posterior known in closed form
@pytest.fixture(scope="module")
def plane_fit(tmp_path_factory):
    """The plane y = a + b x1 + c x2 (tests/linear_gaussian.py), normal priors and a noise sd
    fixed by its prior to 1%, fitted to 24 rows whose x1 and x2 are correlated: a Gaussian
    posterior with correlated coefficients.  Returns (fit, x1, x2) of the data."""
    import linear_gaussian as lg

    from skinfit import paths, registry

    folder = tmp_path_factory.mktemp("plane")
    (folder / "models").mkdir()
    (folder / "priors").mkdir()
    (folder / "models" / "plane_test.toml").write_text(lg.CARD)
    (folder / "priors" / "plane_test.toml").write_text(lg.PRIORS)
    registry.register("forward", lg.FORWARD, lg.plane)
    paths.set_search_path([folder])
    try:
        rng = np.random.default_rng(11)
        x1 = np.linspace(0.0, 2.0, 24)
        x2 = 0.8 * x1 + rng.normal(0.0, 0.3, 24)
        y = 0.3 + 0.8 * x1 - 0.5 * x2 + rng.normal(0.0, 0.2, 24)
        csv = folder / "plane.csv"
        pd.DataFrame({"x1 [V]": x1, "x2 [1]": x2, "y [1]": y}).to_csv(csv, index=False)
        fit = skinfit.fit("plane_test", str(csv), rng=5)
        assert fit.converged
        yield fit, x1, x2
    finally:
        paths.set_search_path([])
        registry.unregister("forward", lg.FORWARD)


PLANE_CANDIDATES = {"grid": {"x1": {"unit": "V", "values": [0.0, 1.0, 2.0, 4.0]},
                             "x2": {"unit": "1", "values": [-1.0, 1.0]}}}


def _plane_truth(result, x1, x2, focus):
    """Closed forms for the plane: the posterior covariance S given the data (noise sd the
    design's), the gain about the coefficients ``focus`` of one more measurement at each
    candidate, 0.5 log det S_ff / det S'_ff, and of the plan's points together."""
    import linear_gaussian as lg

    sigma = result.settings["noise"]["y"]["scale"]
    S = lg.posterior_cov(x1, x2, sigma)
    f = np.ix_(focus, focus)

    def gain(X):
        after = np.linalg.inv(np.linalg.inv(S) + X.T @ X / sigma**2)
        return 0.5 * (np.linalg.slogdet(S[f])[1] - np.linalg.slogdet(after[f])[1])

    t, p = result.table, result.plan
    single = np.array([gain(lg.rows([a], [b])) for a, b in zip(t["x1 [V]"], t["x2 [1]"])])
    return single, gain(lg.rows(p["x1 [V]"].to_numpy(), p["x2 [1]"].to_numpy())), S, sigma


def _agrees(value, se, bias, exact):
    """Agreement within the reported error: 3 standard errors plus the stated bias."""
    return np.abs(np.asarray(value) - exact) <= 3 * np.asarray(se) + np.abs(np.asarray(bias))


def test_design_from_a_fit_gain_about_a_subset_matches_closed_form_with_nuisance_parameters(plane_fit):
    """Issue 39.1: the gain about b (a and c nuisance, correlated with b in the posterior) of one
    more measurement x is 0.5 log(var_post(b) / var_post+x(b)); the old estimator swapped the
    outer draw's b into draws whose a and c did not go with it, and reported a negative gain."""
    fit, x1, x2 = plane_fit
    S = np.cov(np.column_stack([fit.group("posterior")[k].values.ravel() for k in "abc"]), rowvar=False)
    corr = S / np.sqrt(np.outer(np.diag(S), np.diag(S)))
    assert np.abs(corr[1, [0, 2]]).max() > 0.7  # the nuisance parameters go with b
    result = skinfit.design(fit, PLANE_CANDIDATES, n=4, params=["b"], rng=2)
    single, batch, _, _ = _plane_truth(result, x1, x2, [1])
    t = result.table
    assert single.min() < 0.05 and single.max() > 0.5  # the closed forms span small and large gains
    assert _agrees(t["eig"], t["eig_se"], t["eig_bias"], single).all(), (t, single)
    assert (t["eig"] + 2 * t["eig_se"] >= 0).all()
    assert (t["eig_upper"] + 3 * t["eig_upper_se"] >= single).all()  # an upper bound
    plan = result.comparison.loc["plan"]
    assert _agrees(plan["eig_nmc"], plan["eig_nmc_se"], plan["eig_nmc_bias"], batch), (plan, batch)


def test_design_from_a_fit_gain_about_all_parameters_matches_closed_form(plane_fit):
    """Issue 39.1: about all parameters, 0.5 log det(I + X S X^T / sigma^2), S the posterior
    covariance: for one measurement at each candidate and for the plan's points together."""
    import linear_gaussian as lg

    fit, x1, x2 = plane_fit
    result = skinfit.design(fit, PLANE_CANDIDATES, n=4, rng=3)
    single, batch, S, sigma = _plane_truth(result, x1, x2, [0, 1, 2])
    t, p = result.table, result.plan
    rows = lg.rows(t["x1 [V]"].to_numpy(), t["x2 [1]"].to_numpy())
    assert single == pytest.approx(0.5 * np.log1p(np.einsum("ci,ij,cj->c", rows, S, rows) / sigma**2))
    Xp = lg.rows(p["x1 [V]"].to_numpy(), p["x2 [1]"].to_numpy())
    assert batch == pytest.approx(0.5 * np.linalg.slogdet(np.eye(len(Xp)) + Xp @ S @ Xp.T / sigma**2)[1])
    assert _agrees(t["eig"], t["eig_se"], t["eig_bias"], single).all(), (t, single)
    assert (t["eig"] <= single + 3 * t["eig_se"]).all()  # a lower bound about all parameters
    plan = result.comparison.loc["plan"]
    assert _agrees(plan["eig_nmc"], plan["eig_nmc_se"], plan["eig_nmc_bias"], batch), (plan, batch)
