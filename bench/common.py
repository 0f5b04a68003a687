"""Shared harness of the per-model benchmarks (issue 7): the same posterior, one process, one run.

"Converged" is the issue's criterion for every method: rank-normalised R-hat <= 1.01 and
minimum bulk ESS >= 400 over all parameters, both by ArviZ 1.x (``arviz.rhat``,
``arviz.ess(method="bulk")``), emcee walkers counted as chains.  Each method reports wall time
to that point, ESS per second (minimum over parameters), log-density evaluations per second
and peak memory (resident set growth above the level at the method's start, polled every
20 ms; the process-wide ``ru_maxrss`` is stated with the machine).
"""

import os
import platform
import resource
import subprocess
import threading
import time
import warnings
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

import arviz as az
import emcee
import numpy as np

import skinfit
from skinfit.moves import default_moves
from skinfit.optimize import find_map, laplace_covariance
from skinfit.posterior import Posterior
from skinfit.sampling import initial_ball

ESS_TARGET = 400
RHAT_MAX = 1.01
RESULTS = Path(__file__).resolve().parent / "results"


@dataclass
class Result:
    """One method's row of a results table."""

    method: str
    wall_s: float
    min_ess: float
    max_rhat: float
    evaluations: int
    peak_mb: float
    note: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def converged(self):
        return bool(self.min_ess >= ESS_TARGET and self.max_rhat <= RHAT_MAX)


def diagnostics(draws):
    """(min bulk ESS, max rank R-hat) over parameters of ``draws`` (chains, draws, d), by ArviZ."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ess = az.ess(draws, method="bulk", chain_axis=0, draw_axis=1)
        rhat = az.rhat(draws, chain_axis=0, draw_axis=1)
    return float(np.min(ess)), float(np.max(rhat))


class PeakRSS:
    """Context manager: peak resident-set growth [MB] above the level at entry (20 ms polls)."""

    _page = os.sysconf("SC_PAGE_SIZE")

    def _rss(self):
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * self._page

    def __enter__(self):
        self.base = self.peak = self._rss()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._poll, daemon=True)
        self._thread.start()
        return self

    def _poll(self):
        while not self._stop.wait(0.02):
            self.peak = max(self.peak, self._rss())

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, self._rss())
        self.mb = (self.peak - self.base) / 2**20
        return False


def machine_info():
    """Dict of the facts a results file states about the machine and software."""
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")), platform.processor())
    versions = {}
    for pkg in ("skinfit", "numpy", "emcee", "arviz", "dynesty", "pymc", "pytensor"):
        try:
            versions[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            versions[pkg] = "not installed"
    return {"nproc": os.cpu_count(), "cpu": cpu, "python": platform.python_version(), "versions": versions,
            "uptime": subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip(),
            "ru_maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def fit_sequence(post, seed, n_global=2000, n_local=2, nwalkers=None):
    """The start :func:`skinfit.fit` uses, drawn from the same seed in the same order:
    (MAP result, walkers p0, emcee random state, rng)."""
    rng = np.random.default_rng(seed)
    map_result = find_map(post, rng, n_global=n_global, n_local=n_local)
    z_map = post.to_z(map_result.theta[None])[0]
    nwalkers = nwalkers or max(32, 2 * ((4 * post.ndim + 1) // 2))
    p0 = initial_ball(post, z_map, laplace_covariance(post, z_map), nwalkers, rng)
    state = np.random.RandomState(int(rng.integers(2**32 - 1))).get_state()
    return map_result, p0, state, rng


def run_skinfit(model, dataset, priors, seed):
    """``skinfit.fit`` with its defaults; ArviZ diagnostics on the posterior it returns."""
    with PeakRSS() as mem:
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = skinfit.fit(model, dataset, priors=priors, rng=seed)
        wall = time.perf_counter() - t0
    post = fit.idata["posterior"].to_dataset()
    draws = np.stack([post[v].values for v in post.data_vars], axis=-1)
    ess, rhat = diagnostics(draws)
    s, t = fit.attr("sampler"), fit.attr("timings")
    evals = fit.attr("support_counts")["evaluations"]
    note = (f"own criteria {'met' if s['converged'] else 'NOT met: ' + '; '.join(s['reasons'])}; "
            f"{s['n_steps']} steps x {s['nwalkers']} walkers, max tau {max(s['tau'].values()):.0f}, "
            f"MAP {t['map_s']:.1f} s, sampling {t['sampling_s']:.1f} s")
    return Result("skinfit.fit", wall, ess, rhat, evals, mem.mb, note,
                  extra={"fit": fit, "timings": t, "sampler": s})


def run_bare_emcee(post, seed, chunk=1000, max_steps=40000, burn_fraction=0.25, max_draws=1000):
    """emcee over skinfit's own log-density ``post(z)``, same moves, walkers and start as
    ``skinfit.fit`` (same seed, hence the same chain), run in chunks of ``chunk`` steps until
    ArviZ's criteria hold on the chain after discarding ``burn_fraction`` of it (thinned to at
    most ``max_draws`` per walker for the check)."""
    with PeakRSS() as mem:
        t0 = time.perf_counter()
        map_result, p0, state, _ = fit_sequence(post, seed)
        t_map = time.perf_counter() - t0
        sampler = emcee.EnsembleSampler(len(p0), post.ndim, post, vectorize=True, moves=default_moves())
        state = emcee.State(p0, random_state=state)
        t_checks, marks = 0.0, [(0, t_map)]
        while sampler.iteration < max_steps:
            state = sampler.run_mcmc(state, chunk, progress=False)
            marks.append((sampler.iteration, time.perf_counter() - t0))
            tc = time.perf_counter()
            chain = sampler.get_chain()
            n = chain.shape[0]
            kept = chain[int(burn_fraction * n):]
            kept = kept[::max(1, int(np.ceil(len(kept) / max_draws)))]
            theta = post.to_theta(kept.reshape(-1, post.ndim)).reshape(kept.shape).transpose(1, 0, 2)
            ess, rhat = diagnostics(theta)
            t_checks += time.perf_counter() - tc
            if ess >= ESS_TARGET and rhat <= RHAT_MAX:
                break
        wall = time.perf_counter() - t0
    note = (f"{sampler.iteration} steps x {len(p0)} walkers (chunks of {chunk}); MAP {t_map:.1f} s, "
            f"checks {t_checks:.1f} s")
    return Result("bare emcee loop on skinfit's log-density", wall, ess, rhat, post.counts["evaluations"],
                  mem.mb, note, extra={"chain": sampler.get_chain(), "steps": sampler.iteration,
                                       "map_s": t_map, "checks_s": t_checks, "marks": marks})


def wall_at_step(marks, n):
    """Wall time [s] the bare loop had spent (MAP included, its checks excluded) when its chain
    reached ``n`` steps, interpolated between chunk ends; None if it stopped earlier."""
    steps, walls = np.array(marks, dtype=float).T
    return float(np.interp(n, steps, walls)) if n <= steps[-1] else None


def run_dynesty(post, seed, nlive=400, sample="rslice", maxcall=None):
    """dynesty static nested sampling (default stopping dlogz) on the natural parameters.

    ESS is dynesty's own estimate, the Kish effective size of the importance weights
    (``dynesty.utils.get_neff_from_logwt``); R-hat is ArviZ's over 4 random quarters of the
    equal-weight resample (``results.samples_equal``).
    """
    import dynesty
    from dynesty.utils import get_neff_from_logwt

    def loglike(theta):
        value = post.log_likelihood(theta[None])[0]
        return value if np.isfinite(value) else -1e300

    def prior_transform(u):
        return post.prior_transform(u[None])[0]

    with PeakRSS() as mem:
        t0 = time.perf_counter()
        rstate = np.random.default_rng(seed)
        sampler = dynesty.NestedSampler(loglike, prior_transform, post.ndim, nlive=nlive, sample=sample,
                                        rstate=rstate)
        sampler.run_nested(maxcall=maxcall, print_progress=False)
        res = sampler.results
        wall = time.perf_counter() - t0
    ess = float(get_neff_from_logwt(res.logwt))
    equal = res.samples_equal(rstate=rstate)
    equal = equal[rstate.permutation(len(equal))][: 4 * (len(equal) // 4)]
    _, rhat = diagnostics(equal.reshape(4, -1, post.ndim))
    evals = int(np.sum(res.ncall))
    return Result(f"dynesty {sample}, {nlive} live", wall, ess, rhat, evals, mem.mb,
                  f"logZ {res.logz[-1]:.2f} +- {res.logzerr[-1]:.2f}; {len(res.logl)} dead+live points"
                  + (f"; stopped at maxcall {maxcall}" if maxcall and evals >= maxcall else ""))


def throughput(func, z, seconds=1.0):
    """Log-density evaluations per second of ``func`` on the ensemble ``z`` (k, d)."""
    func(z)
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        func(z)
        n += 1
    return n * len(z) / (time.perf_counter() - t0)


def table(rows):
    """Markdown table of results, with ratios to the first row's wall time."""
    lines = ["| method | wall s | x skinfit | min bulk ESS | max R-hat | ESS/s | log-density evals | evals/s "
             "| peak RSS growth MB | converged | notes |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    ref = rows[0].wall_s
    for r in rows:
        lines.append(f"| {r.method} | {r.wall_s:.1f} | {r.wall_s / ref:.2f} | {r.min_ess:.0f} | {r.max_rhat:.4f} | "
                     f"{r.min_ess / r.wall_s:.1f} | {r.evaluations} | {r.evaluations / r.wall_s:.0f} | "
                     f"{r.peak_mb:.0f} | {'yes' if r.converged else 'NO'} | {r.note} |")
    return "\n".join(lines)


def machine_text(info):
    v = info["versions"]
    return (f"Machine: {info['nproc']} CPUs ({info['cpu']}), shared with other jobs; Python {info['python']}, "
            + ", ".join(f"{k} {val}" for k, val in v.items())
            + f". `uptime` at the end: {info['uptime']}. Process peak RSS (ru_maxrss) {info['ru_maxrss_mb']:.0f} MB.")


def posterior_for(model, dataset, priors):
    """skinfit's Posterior for (model id, dataset id, PriorSet), as ``skinfit.fit`` builds it."""
    return Posterior(skinfit.load_model(model), priors, skinfit.load_dataset(dataset))
