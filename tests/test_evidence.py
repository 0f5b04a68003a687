"""Evidence estimators against closed forms, quadrature and each other (issue 8)."""

import math
import re

import numpy as np
import pytest
from scipy import stats
from scipy.special import logsumexp

import skinfit
from skinfit.analysis.evidence import LaplaceError, bayes_factor_strength, bridge_sampling, laplace, nested
from skinfit.apps.cli import main

# ---- a linear-Gaussian model: log Z in closed form ----------------------------------------

class LinearGaussian:
    """y = X b + e, e ~ N(0, s^2 I), b ~ N(0, t^2 I): posterior and evidence are exact."""

    def __init__(self, d=5, n=40, s=0.5, t=2.0, seed=3):
        rng = np.random.default_rng(seed)
        self.X = rng.normal(size=(n, d))
        self.b = rng.normal(0, t, size=d)
        self.y = self.X @ self.b + rng.normal(0, s, size=n)
        self.s, self.t, self.d = s, t, d
        cov_y = s**2 * np.eye(n) + t**2 * self.X @ self.X.T
        self.log_z = stats.multivariate_normal(np.zeros(n), cov_y).logpdf(self.y)
        prec = self.X.T @ self.X / s**2 + np.eye(d) / t**2
        self.post_cov = np.linalg.inv(prec)
        self.post_mean = self.post_cov @ self.X.T @ self.y / s**2

    def loglike(self, b):
        r = self.y - np.atleast_2d(b) @ self.X.T
        return -0.5 * np.sum(r**2, axis=-1) / self.s**2 - len(self.y) * math.log(self.s * math.sqrt(2 * math.pi))

    def log_target(self, b):
        b = np.atleast_2d(b)
        return self.loglike(b) + stats.norm(0, self.t).logpdf(b).sum(axis=-1)

    def draws(self, n, rng):
        return rng.multivariate_normal(self.post_mean, self.post_cov, size=n)

    def prior_transform(self, u):
        return stats.norm(0, self.t).ppf(u)


@pytest.fixture(scope="module")
def lg():
    return LinearGaussian()


def test_bridge_matches_closed_form(lg, rng):
    est = bridge_sampling(lg.log_target, lg.draws(4000, rng), rng=rng)
    assert abs(est.log_z - lg.log_z) < 0.1
    assert abs(est.log_z - lg.log_z) < 3 * est.se
    assert 0 < est.se < 0.05
    assert est.method == "bridge" and not est.approximate


def test_laplace_is_exact_for_a_gaussian_posterior(lg):
    est = laplace(lg.log_target, lg.post_mean)
    assert est.log_z == pytest.approx(lg.log_z, abs=1e-6)
    assert est.approximate and math.isnan(est.se)


def test_nested_matches_closed_form(rng):
    small = LinearGaussian(d=3, n=30)
    est = nested(lambda b: float(small.loglike(b)[0]), small.prior_transform, small.d, rng=rng, nlive=200,
                 sample="unif")
    assert abs(est.log_z - small.log_z) < 3 * est.se
    assert abs(est.log_z - small.log_z) < 0.25  # dynesty's own error here is ~0.15 nats


def test_naive_harmonic_mean_fails_the_same_check(lg, rng):
    """Negative control: the tolerance above is tight enough to reject a known-bad estimator."""
    draws = lg.draws(4000, rng)
    harmonic = -(logsumexp(-lg.loglike(draws)) - math.log(len(draws)))
    assert abs(harmonic - lg.log_z) > 1.0


def test_bridge_error_is_honest(lg):
    """Across fresh draws the spread of estimates matches the reported error within 2x."""
    estimates, errors = [], []
    for seed in range(30):
        rng = np.random.default_rng(seed)
        est = bridge_sampling(lg.log_target, lg.draws(600, rng), rng=rng)
        estimates.append(est.log_z)
        errors.append(est.se)
    spread, reported = np.std(estimates, ddof=1), np.sqrt(np.mean(np.square(errors)))
    assert 0.5 < spread / reported < 2.0, (spread, reported)


def test_bridge_error_accounts_for_autocorrelation(lg):
    """Correlated draws (AR(1), rho = 0.9): with their ESS passed, the error stays honest."""
    rho, n = 0.9, 3000
    estimates, errors = [], []
    chol = np.linalg.cholesky(lg.post_cov)
    for seed in range(20):
        rng = np.random.default_rng(100 + seed)
        w = np.empty((n, lg.d))
        w[0] = rng.standard_normal(lg.d)
        noise = rng.standard_normal((n, lg.d)) * math.sqrt(1 - rho**2)
        for i in range(1, n):
            w[i] = rho * w[i - 1] + noise[i]
        draws = lg.post_mean + w @ chol.T
        est = bridge_sampling(lg.log_target, draws, rng=rng, ess=n * (1 - rho) / (1 + rho))
        estimates.append(est.log_z)
        errors.append(est.se)
    spread, reported = np.std(estimates, ddof=1), np.sqrt(np.mean(np.square(errors)))
    assert 0.5 < spread / reported < 2.0, (spread, reported)
    assert abs(np.mean(estimates) - lg.log_z) < 0.05


def test_repeats_report_their_spread(lg, rng):
    est = bridge_sampling(lg.log_target, lg.draws(2000, rng), rng=rng, n_repeats=4)
    assert len(est.repeats) == 4 and np.mean(est.repeats) == pytest.approx(est.log_z)
    assert est.se >= np.std(est.repeats, ddof=1)


def test_bad_draws_are_refused(lg, rng):
    draws = lg.draws(200, rng)
    draws[3, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        bridge_sampling(lg.log_target, draws, rng=rng)
    with pytest.raises(ValueError, match="n >= 4"):
        bridge_sampling(lg.log_target, draws[:10], rng=rng)


def test_laplace_refuses_a_non_maximum(lg):
    with pytest.raises(LaplaceError, match="not finite at the starting point"):
        laplace(lambda z: np.full(len(z), -np.inf), lg.post_mean)
    with pytest.raises(LaplaceError, match="no maximum near the MAP .* along coordinate"):
        laplace(lambda z: np.sum(np.atleast_2d(z) ** 2, axis=-1), np.zeros(2))


# ---- Laplace near a prior bound (issue 39): the Gaussian integrated over the bounds ----------

class BoundedLinearGaussian(LinearGaussian):
    """The linear-Gaussian model with its normal prior truncated to a box: the posterior is the
    Gaussian posterior truncated to the box, and log Z = log Z_open + log P_post(box) -
    log P_prior(box) in closed form (normal CDFs; one 1-D quadrature for a 2-D box)."""

    def __init__(self, upper, d=3, n=30):
        super().__init__(d=d, n=n)
        self.lo, self.hi = np.full(d, -np.inf), np.asarray(upper, dtype=float)
        sd = np.sqrt(np.diag(self.post_cov))
        bounded = np.flatnonzero(np.isfinite(self.hi))
        log_prior_mass = float(np.sum(stats.norm.logcdf(self.hi[bounded] / self.t)))
        if len(bounded) == 1:
            (i,) = bounded
            post_mass = stats.norm.cdf((self.hi[i] - self.post_mean[i]) / sd[i])
        else:  # P(b_i < u_i, b_j < u_j) = int_{-inf}^{u_i} phi_i(a) P(b_j < u_j | b_i = a) da
            i, j = bounded
            c = self.post_cov
            slope, cond_sd = c[i, j] / c[i, i], math.sqrt(c[j, j] - c[i, j] ** 2 / c[i, i])
            from scipy.integrate import quad

            post_mass = quad(lambda a: stats.norm.pdf(a, self.post_mean[i], sd[i]) * stats.norm.cdf(
                (self.hi[j] - self.post_mean[j] - slope * (a - self.post_mean[i])) / cond_sd),
                -np.inf, self.hi[i], epsabs=1e-13, epsrel=1e-11)[0]
        self.log_z_box = self.log_z + math.log(post_mass) - log_prior_mass
        self.post_mass = post_mass
        self._log_prior_mass = log_prior_mass

    def log_target(self, b):
        b = np.atleast_2d(b)
        inside = np.all(b <= self.hi, axis=1)
        return np.where(inside, super().log_target(b) - self._log_prior_mass, -np.inf)

    def draws(self, n, rng):
        out = super().draws(20 * n, rng)
        return out[np.all(out <= self.hi, axis=1)][:n]


def _upper(shifts, d=3):
    """Upper bounds at the open posterior's mean + ``shifts`` sd (inf where None)."""
    open_ = LinearGaussian(d=d, n=30)
    sd = np.sqrt(np.diag(open_.post_cov))
    return [np.inf if k is None else open_.post_mean[i] + k * sd[i] for i, k in enumerate(shifts)]


@pytest.mark.parametrize("shifts", [(-1.5, None, None), (0.3, None, None), (1.5, None, None),
                                    (-0.5, 0.2, None), (-2.0, -1.0, None)],
                         ids=["mode-beyond-bound", "mode-at-bound", "mode-inside-near-bound", "two-bounds",
                              "two-bounds-far-beyond"])
def test_laplace_near_a_prior_bound_matches_the_closed_form(shifts):
    """A posterior cut by prior bounds (the mode beyond, at or inside a bound; one or two bounded
    coordinates): the Laplace value equals the closed form (exact: the log target is quadratic
    inside the box), where the old Gaussian over all space was off by -log P_post(box) or
    raised (the stencil crossed the bound)."""
    model = BoundedLinearGaussian(_upper(shifts))
    start = np.minimum(model.post_mean, model.hi)  # a MAP pressed against the bound
    est = laplace(model.log_target, start, lower=model.lo, upper=model.hi)
    assert model.post_mass < 0.95  # the bound matters: at least 0.05 nats in the closed form
    assert est.log_z == pytest.approx(model.log_z_box, abs=1e-4)
    assert est.approximate and "prior bounds of coordinate 0" in est.caveat


def test_laplace_near_a_prior_bound_is_bracketed_by_the_draws(rng):
    """With posterior draws the caveat gives an evidence bracket that holds the closed form."""
    model = BoundedLinearGaussian(_upper((0.3, None, None)))
    est = laplace(model.log_target, np.minimum(model.post_mean, model.hi), lower=model.lo, upper=model.hi,
                  draws=model.draws(3000, rng), rng=rng, names=["b0", "b1", "b2"])
    low, high = est.details["elbo"], est.details["eubo"]
    assert low - 3 * est.details["elbo_se"] - 1e-9 <= model.log_z_box <= high + 3 * est.details["eubo_se"] + 1e-9
    assert high - low < 0.02  # a Gaussian target: the bracket closes on it (here to rounding)
    assert "prior bounds of b0" in est.caveat and f"within [{low:.2f}, {high:.2f}]" in est.caveat


def test_laplace_refuses_a_gaussian_the_draws_contradict(rng):
    """Where the curvature at the mode misdescribes the posterior (a fine ripple on a standard
    normal: the Hessian sees the ripple, 2.3 nats too narrow), the draws' bracket excludes the
    Laplace value: refused in one line, not a number 2 nats off."""
    def ripple(z):
        z = np.atleast_2d(z)[:, 0]
        return -0.5 * z**2 + 0.01 * np.cos(z / 0.01) - 0.5 * math.log(2 * math.pi)  # log Z = 0.00002

    assert laplace(ripple, [0.0]).log_z < -1.0  # unchecked, the value is > 1 nat off
    with pytest.raises(LaplaceError, match=r"does not describe this posterior: .* lies outside"):
        laplace(ripple, [0.0], draws=rng.standard_normal((4000, 1)), rng=rng)


def test_laplace_caveat_states_a_loose_bracket(rng):
    """A spike on a broad bump (equal masses): Laplace sees the spike alone (log Z -0.68, truth 0).
    The draws cannot refute that value, but they bound log Z only loosely, and the caveat says
    so with a bracket that holds the truth."""
    def spike(z):
        z = np.atleast_2d(z)[:, 0]
        return np.logaddexp(stats.norm.logpdf(z, 0, 0.01), stats.norm.logpdf(z)) + math.log(0.5)

    draws = np.where(rng.uniform(size=4000) < 0.5, 0.01, 1.0) * rng.standard_normal(4000)
    est = laplace(spike, [0.0], draws=draws[:, None], rng=rng)
    low, high = est.details["elbo"], est.details["eubo"]
    assert est.log_z == pytest.approx(-0.68, abs=0.02)
    assert low - 3 * est.details["elbo_se"] <= 0.0 <= high and high - low > 100
    assert f"the posterior draws bound log Z within [{low:.2f}, {high:.2f}]" in est.caveat


@pytest.mark.parametrize("log_bf, words", [(0.5, "not worth more than a bare mention"), (2.0, "positive"),
                                           (4.0, "strong"), (6.0, "very strong"), (-4.0, "strong")])
def test_kass_raftery_scale(log_bf, words):
    assert bayes_factor_strength(log_bf) == words


# ---- through the engine: Coulomb friction at 0 V, a 2-D likelihood -------------------------

PRIORS = """
schema_version = 1
model = "electroadhesion_coulomb"
[mu]
dist = "uniform"
bounds = [0.0, {mu_hi}]
source = "electroadhesion_friction"
[E_star]
{e_star}
source = "electroadhesion_friction, test: ignored by the likelihood at 0 V"
[d_air]
{d_air}
source = "electroadhesion_friction, test: ignored by the likelihood at 0 V"
[sigma]
dist = "uniform"
bounds = [0.005, 0.2]
source = "electroadhesion_friction"
"""


@pytest.fixture(scope="module")
def zero_volt():
    ds = skinfit.load_dataset("electroadhesion_synthetic")
    return ds.subset(ds.frame["voltage"].to_numpy() == 0.0, "0V")


FLAT = ('dist = "uniform"\nbounds = [2e3, {e_hi}]', 'dist = "loguniform"\nbounds = [1e-9, 5e-6]')
ROUND = ('dist = "lognormal"\nmedian = 40e3\nsigma = 0.3\nbounds = [1e3, 1e6]',
         'dist = "lognormal"\nmedian = 0.5e-6\nsigma = 0.5\nbounds = [1e-9, 1e-4]')


def _priors(tmp_path, name, mu_hi=2.0, e_hi=100e3, ignored=FLAT):
    path = tmp_path / f"{name}.toml"
    path.write_text(PRIORS.format(mu_hi=mu_hi, e_star=ignored[0].format(e_hi=e_hi), d_air=ignored[1]))
    return skinfit.load_priors(path)


@pytest.fixture(scope="module")
def coulomb_fits(tmp_path_factory, zero_volt):
    tmp = tmp_path_factory.mktemp("priors")
    fits = {}
    for name, mu_hi, e_hi, ignored in [("base", 2.0, 100e3, FLAT), ("wide_mu", 4.0, 100e3, FLAT),
                                       ("wide_e", 2.0, 198e3, FLAT), ("round", 2.0, None, ROUND)]:
        priors = _priors(tmp, name, mu_hi, e_hi, ignored)
        fits[name] = skinfit.fit("electroadhesion_coulomb", zero_volt, priors=priors, rng=7)
    return fits


def _quadrature_log_z(ds, mu_hi):
    """log Z with mu integrated in closed form (Gaussian in mu, normal CDFs over its bounds) and
    sigma by the trapezoid rule: independent of skinfit's likelihood and priors."""
    fn = ds.frame["normal_force"].to_numpy()
    ft = ds.frame["tangential_force"].to_numpy()
    n, S = len(fn), np.sum(fn**2)
    mu_hat = np.sum(fn * ft) / S
    rss = np.sum((ft - mu_hat * fn) ** 2)
    sigma = np.linspace(0.005, 0.2, 20001)
    mass = stats.norm.cdf((mu_hi - mu_hat) * np.sqrt(S) / sigma) - stats.norm.cdf(-mu_hat * np.sqrt(S) / sigma)
    log_f = (-n * np.log(sigma * np.sqrt(2 * np.pi)) - rss / (2 * sigma**2)
             + 0.5 * np.log(2 * np.pi * sigma**2 / S) + np.log(mass))
    w = np.full(sigma.size, sigma[1] - sigma[0])
    w[[0, -1]] /= 2
    return logsumexp(log_f + np.log(w)) - math.log(mu_hi) - math.log(0.2 - 0.005)


def test_bridge_agrees_with_grid_quadrature(coulomb_fits, zero_volt):
    truth = _quadrature_log_z(zero_volt, 2.0)
    est = skinfit.evidence(coulomb_fits["base"])
    assert abs(est.log_z - truth) < 0.05, (est, truth)


def test_laplace_near_gaussian_posterior(coulomb_fits, zero_volt):
    """Ignored parameters with log-normal priors: the posterior is near-Gaussian in the sampling
    coordinates and Laplace lands close to the quadrature (bridge closer still)."""
    truth = _quadrature_log_z(zero_volt, 2.0)
    est = skinfit.evidence(coulomb_fits["round"], method="laplace")
    assert abs(est.log_z - truth) < 0.1 and est.approximate
    assert abs(skinfit.evidence(coulomb_fits["round"]).log_z - truth) < 0.05


def test_laplace_refuses_a_flat_direction(coulomb_fits):
    """A uniform prior on a parameter the data ignore leaves no curvature: a one-line refusal
    naming the fit, the parameter and what to use instead (an InputError: the CLI's exit 2)."""
    with pytest.raises(skinfit.InputError) as err:
        skinfit.evidence(coulomb_fits["base"], method="laplace")
    message = str(err.value)
    assert "\n" not in message and message.startswith("evidence of electroadhesion_coulomb on ")
    assert re.search(r"no maximum near the MAP .* along (E_star|d_air)\b", message)
    assert message.endswith("use method='bridge' (the default)")


def test_laplace_refusal_in_cli_compare_is_one_line(coulomb_fits, tmp_path, capsys):
    """`skinfit compare --method laplace` with a fit Laplace cannot describe: exit 2 and one line
    on stderr naming the fit and why, no traceback, no table."""
    runs = []
    for name in ("round", "base"):
        coulomb_fits[name].save(tmp_path / name / "fit.nc")
        runs.append(str(tmp_path / name))
    capsys.readouterr()
    assert main(["compare", *runs, "--method", "laplace"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("skinfit: error: evidence of electroadhesion_coulomb on ") and "no maximum" in err


def test_prior_width_enters_the_evidence(coulomb_fits):
    """Doubling a uniform prior's range costs ln 2 when the data constrain the parameter (mu),
    and nothing when the likelihood ignores it (E_star at 0 V: the prior integrates to 1)."""
    base = skinfit.evidence(coulomb_fits["base"])
    wide_mu = skinfit.evidence(coulomb_fits["wide_mu"])
    wide_e = skinfit.evidence(coulomb_fits["wide_e"])
    se = math.hypot(base.se, wide_mu.se)
    assert base.log_z - wide_mu.log_z == pytest.approx(math.log(2), abs=max(3 * se, 0.03))
    assert abs(base.log_z - wide_e.log_z) < max(3 * math.hypot(base.se, wide_e.se), 0.03)


def test_evidence_is_saved_with_the_fit(coulomb_fits, tmp_path):
    fit = coulomb_fits["base"]
    est = skinfit.evidence(fit)
    fit.save(tmp_path / "fit.nc")
    again = skinfit.evidence(skinfit.load_fit(tmp_path / "fit.nc"))
    assert again.log_z == est.log_z and again.se == est.se


def test_same_seed_same_estimate(coulomb_fits):
    a = skinfit.evidence(coulomb_fits["base"], rng=5, refresh=True)
    b = skinfit.evidence(coulomb_fits["base"], rng=5, refresh=True)
    assert a.log_z == b.log_z


def test_unknown_method_is_refused(coulomb_fits):
    with pytest.raises(ValueError, match="unknown evidence method"):
        skinfit.evidence(coulomb_fits["base"], method="harmonic_mean")


@pytest.mark.slow
def test_nested_agrees_with_quadrature_through_the_engine(coulomb_fits, zero_volt):
    est = skinfit.evidence(coulomb_fits["base"], method="nested", rng=3)
    assert abs(est.log_z - _quadrature_log_z(zero_volt, 2.0)) < 3 * est.se + 0.05
