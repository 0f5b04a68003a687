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
from skinfit.inference.run import default_walkers, start
from skinfit.inference.sampling import _adapt, adaptive_moves, independence_move
from skinfit.posterior import Posterior

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


def user_env(env=None):
    """``env`` (default: this process's environment) as a user's shell has it: Python writes
    and reads its bytecode caches (.pyc, as pip writes them at install), which
    PYTHONDONTWRITEBYTECODE, set in some sandboxes and CI images, turns off, so that every
    process would compile skinfit's modules again (~0.15 s for ``skinfit demo``)."""
    env = dict(os.environ if env is None else env)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def timed_skinfit(args, log, env=None, cwd=None):
    """(wall s, user + sys CPU s of the process and its children) of ``python -m skinfit ARGS``
    as a new process (in :func:`user_env`); its output written to ``log``, a failure raised with it."""
    import sys

    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "skinfit", *args], capture_output=True, text=True, env=user_env(env),
                         cwd=cwd)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    Path(log).write_text(out.stdout + out.stderr)
    if out.returncode:
        raise SystemExit(f"skinfit {' '.join(args)} failed ({out.returncode}); see {log}")
    return wall, r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime


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


def fit_start(post, seed):
    """The start :func:`skinfit.fit` makes from ``seed``, drawn in the same order: (MAP result,
    initial proposal, walkers p0, emcee's RandomState state)."""
    rng = np.random.default_rng(seed)
    map_result, proposal, p0, _ = start(post, rng, nwalkers=default_walkers(post))
    emcee_seed = int(rng.integers(2**32 - 1))  # run_emcee's first draw
    return map_result, proposal, p0, emcee_seed


def run_skinfit(model, dataset, priors, seed):
    """``skinfit.fit`` with its defaults on a loaded model, dataset and priors (reading the
    files is outside every method's timing): wall time and memory to the converged posterior;
    ArviZ diagnostics on that posterior; then, timed apart (``extra["pointwise_s"]`` and
    ``["pointwise_mb"]``), the pointwise log-likelihood and predictive draws (``Fit.complete``)."""
    with PeakRSS() as mem:
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = skinfit.fit(model, dataset, priors=priors, rng=seed, complete=False)
        wall = time.perf_counter() - t0
    post = fit.group("posterior")
    draws = np.stack([post[v].values.reshape(post.sizes["chain"], post.sizes["draw"], -1) for v in post.data_vars],
                     axis=-1).reshape(post.sizes["chain"], post.sizes["draw"], -1)
    ess, rhat = diagnostics(draws)
    with PeakRSS() as mem_pointwise:
        fit.complete()
    s, t = fit.attr("sampler"), fit.attr("timings")  # t["pointwise_s"]: the completion's own time
    evals = fit.attr("support_counts")["evaluations"]
    refits = [a["step"] for a in s.get("adaptation", []) if a["refit"]]
    note = (f"own criteria {'met' if s['converged'] else 'NOT met: ' + '; '.join(s['reasons'])}; "
            f"{s['n_steps']} steps x {s['nwalkers']} walkers, refits at {refits}, max tau {max(s['tau'].values()):.1f}, "
            f"MAP {t['map_s']:.2f} s, importance start {t['start_s'] - t['map_s']:.2f} s, sampling {t['sampling_s']:.2f} s, "
            f"result tree {t['tree_s']:.2f} s, pointwise + predictive {t['pointwise_s']:.2f} s "
            f"({mem_pointwise.mb:.0f} MB)")
    return Result("skinfit.fit", wall, ess, rhat, evals, mem.mb, note,
                  extra={"fit": fit, "timings": t, "sampler": s, "pointwise_s": t["pointwise_s"],
                         "pointwise_mb": mem_pointwise.mb})


def run_bare_emcee(model, dataset, priors, seed, sampler_record):
    """The chain ``skinfit.fit`` ran, by emcee alone: ``emcee.EnsembleSampler(vectorize=True)``
    over skinfit's own log-density ``post(z)``, from the same start (MAP, Laplace proposal,
    walkers, seed), with skinfit's moves, refitting the proposal at the steps the fit's record
    says (``skinfit.inference.sampling._adapt``), to the fit's step count: the identical chain, hence the
    same ESS, without skinfit's convergence checks, guard rails and result tree.  Timed like the
    fit (from loaded model, dataset and priors: the Posterior is built inside the timing).
    Returns the wall time split into MAP + start and sampling; ESS/R-hat of the same kept draws
    as the fit's."""
    with PeakRSS() as mem:
        t0 = time.perf_counter()
        post = Posterior(model, priors, dataset)
        map_result, proposal, p0, emcee_seed = fit_start(post, seed)
        t_start = time.perf_counter() - t0
        move = independence_move(proposal)
        sampler = emcee.EnsembleSampler(len(p0), post.ndim, post, vectorize=True, moves=adaptive_moves(move))
        state = emcee.State(p0, random_state=np.random.RandomState(emcee_seed).get_state())
        refits = [a["step"] for a in sampler_record["adaptation"] if a["refit"]]
        for stop in refits + [sampler_record["n_steps"]]:
            state = sampler.run_mcmc(state, stop - sampler.iteration, progress=False, skip_initial_state_check=True)
            if stop in refits:
                move.proposal = _adapt(sampler.get_chain(), emcee_seed, proposal.nu)
        wall = time.perf_counter() - t0
    chain = sampler.get_chain()[sampler_record["burn"]::sampler_record["thin"]]
    theta = post.to_theta(chain.reshape(-1, post.ndim)).reshape(chain.shape).transpose(1, 0, 2)
    ess, rhat = diagnostics(theta)
    note = (f"{sampler.iteration} steps x {len(p0)} walkers (the fit's), refits at {refits}; "
            f"MAP and start {t_start:.2f} s, sampling {wall - t_start:.2f} s")
    return Result("bare emcee loop, skinfit's moves (same chain)", wall, ess, rhat, post.counts["evaluations"],
                  mem.mb, note, extra={"chain": sampler.get_chain(), "start_s": t_start})


def run_plain_emcee(post, seed, chunk=1000, max_steps=40000, burn_fraction=0.25, max_draws=1000):
    """What a hand-written emcee loop gets: differential-evolution moves (emcee's ``DEMove``)
    over skinfit's log-density in its sampling coordinates (log for positive parameters), from
    skinfit's MAP ball, in chunks of ``chunk`` steps until ArviZ's criteria hold on the chain
    after discarding ``burn_fraction`` of it (thinned to at most ``max_draws`` per walker)."""
    with PeakRSS() as mem:
        t0 = time.perf_counter()
        map_result, proposal, p0, emcee_seed = fit_start(post, seed)
        t_map = time.perf_counter() - t0
        sampler = emcee.EnsembleSampler(len(p0), post.ndim, post, vectorize=True, moves=emcee.moves.DEMove())
        state = emcee.State(p0, random_state=np.random.RandomState(emcee_seed).get_state())
        t_checks = 0.0
        while sampler.iteration < max_steps:
            state = sampler.run_mcmc(state, chunk, progress=False)
            tc = time.perf_counter()
            chain = sampler.get_chain()
            kept = chain[int(burn_fraction * len(chain)):]
            kept = kept[::max(1, int(np.ceil(len(kept) / max_draws)))]
            theta = post.to_theta(kept.reshape(-1, post.ndim)).reshape(kept.shape).transpose(1, 0, 2)
            ess, rhat = diagnostics(theta)
            t_checks += time.perf_counter() - tc
            if ess >= ESS_TARGET and rhat <= RHAT_MAX:
                break
        wall = time.perf_counter() - t0
    note = (f"{sampler.iteration} steps x {len(p0)} walkers (chunks of {chunk}); MAP {t_map:.2f} s, "
            f"checks {t_checks:.2f} s")
    return Result("plain emcee loop, DE moves", wall, ess, rhat, post.counts["evaluations"], mem.mb, note)


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


def throughput(funcs, z, seconds=0.5, repeats=4):
    """Log-density evaluations per second of each of the functions ``funcs`` on the ensemble
    ``z`` (k, d), a list: the best of ``repeats`` runs of ``seconds`` each (as
    ``timeit`` takes the minimum), the functions' runs alternating, so that a change of load on
    this shared machine meets all of them (run one after the other, single runs of the same
    code varied by 1.6-2.3x in their ratio to the fused expression, and the best of four by
    1.65-2.11 on contact_area in three runs of one day)."""
    best = [0.0] * len(funcs)
    for f in funcs:
        f(z)
    for _ in range(repeats):
        for i, f in enumerate(funcs):
            n, t0 = 0, time.perf_counter()
            while time.perf_counter() - t0 < seconds:
                f(z)
                n += 1
            best[i] = max(best[i], n * len(z) / (time.perf_counter() - t0))
    return best


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
