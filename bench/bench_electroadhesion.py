"""Electroadhesion: skinfit vs a bare emcee loop on skinfit's own log-density vs dynesty.

    python bench/bench_electroadhesion.py [--priors bench/priors_electroadhesion_uniform.toml]

Same data (datasets/electroadhesion_synthetic, 216 rows), same priors (uniform on the paper's
Table I ranges by default, as in issue 7), one process, one run. "Converged" means the
issue's criterion for every method: rank-normalised R-hat <= 1.01 and minimum bulk ESS >= 400
over all parameters (ArviZ, walkers as chains for emcee). Appends a table to
bench/results/electroadhesion.md with the machine and its load.
"""

import argparse
import os
import platform
import resource
import time
from pathlib import Path

import arviz as az
import emcee
import numpy as np

import skinfit
from skinfit.moves import default_moves
from skinfit.optimize import find_map, laplace_covariance
from skinfit.posterior import Posterior
from skinfit.sampling import initial_ball

HERE = Path(__file__).resolve().parent
DATA = "electroadhesion_synthetic"


def diagnostics(chain):
    """(min bulk ESS, max R-hat) of a (chains, draws, d) array by ArviZ."""
    ds = az.convert_to_dataset({f"p{j}": chain[:, :, j] for j in range(chain.shape[-1])})
    ess = float(min(v.item() for v in az.ess(ds, method="bulk").data_vars.values()))
    rhat = float(max(v.item() for v in az.rhat(ds).data_vars.values()))
    return ess, rhat


def run_skinfit(priors, seed):
    t0 = time.perf_counter()
    fit = skinfit.fit("electroadhesion", DATA, priors=priors, rng=seed)
    wall = time.perf_counter() - t0
    post = fit.idata["posterior"].to_dataset()
    ess = float(min(az.ess(post, method="bulk")[v].min() for v in post.data_vars))
    rhat = float(max(az.rhat(post)[v].max() for v in post.data_vars))
    evals = fit.attr("sampler")["evaluations"]
    return {"method": "skinfit.fit", "wall_s": wall, "min_ess_bulk": ess, "max_rhat": rhat, "evals": evals,
            "converged": fit.converged and ess >= 400 and rhat <= 1.01}


def run_bare_emcee(priors, seed, chunk=500, max_steps=40000):
    """MAP + Laplace ball + emcee with skinfit's moves, checked every ``chunk`` steps."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    post = Posterior(skinfit.load_model("electroadhesion"), priors, skinfit.load_dataset(DATA))
    z0 = post.to_z(find_map(post, rng).theta[None])[0]
    nwalkers = max(32, 2 * ((4 * post.ndim + 1) // 2))
    p0 = initial_ball(post, z0, laplace_covariance(post, z0), nwalkers, rng)
    sampler = emcee.EnsembleSampler(nwalkers, post.ndim, post, vectorize=True, moves=default_moves())
    sampler._random = np.random.mtrand.RandomState(int(rng.integers(2**31)))
    state = p0
    while sampler.iteration < max_steps:
        state = sampler.run_mcmc(state, chunk, progress=False)
        chain = sampler.get_chain()[sampler.iteration // 4:].transpose(1, 0, 2)
        ess, rhat = diagnostics(post.to_theta(chain.reshape(-1, post.ndim)).reshape(chain.shape))
        if ess >= 400 and rhat <= 1.01:
            break
    return {"method": "bare emcee loop (same log-density, moves, start)", "wall_s": time.perf_counter() - t0,
            "min_ess_bulk": ess, "max_rhat": rhat, "evals": post.counts["evaluations"],
            "converged": ess >= 400 and rhat <= 1.01}


def run_dynesty(priors, seed):
    import dynesty

    post = Posterior(skinfit.load_model("electroadhesion"), priors, skinfit.load_dataset(DATA))
    t0 = time.perf_counter()

    def loglike(theta):
        value = post.log_likelihood(theta[None])[0]
        return value if np.isfinite(value) else -1e300

    sampler = dynesty.NestedSampler(loglike, lambda u: post.prior_transform(u[None])[0], post.ndim,
                                    nlive=400, sample="rslice", rstate=np.random.default_rng(seed))
    sampler.run_nested(dlogz=0.1, print_progress=False)
    res = sampler.results
    wall = time.perf_counter() - t0
    w = np.exp(res.logwt - res.logz[-1])
    ess = float(w.sum() ** 2 / (w**2).sum())  # Kish ESS of the weighted samples (dynesty's own measure)
    return {"method": "dynesty rslice, 400 live", "wall_s": wall, "min_ess_bulk": ess, "max_rhat": float("nan"),
            "evals": int(np.sum(res.ncall)), "converged": ess >= 400}


def fused_throughput(priors, nwalkers=32, repeats=200):
    """Evaluations per second: skinfit's log-density vs one fused numpy expression."""
    from skinfit.physics.electroadhesion import electroadhesion

    model = skinfit.load_model("electroadhesion")
    ds = skinfit.load_dataset(DATA)
    post = Posterior(model, priors, ds)
    rng = np.random.default_rng(0)
    z = post.to_z(post.sample_prior(nwalkers, rng))
    x = {c: ds.frame[c].to_numpy() for c in ("normal_force", "voltage")}
    y = ds.frame["tangential_force"].to_numpy()
    c = dict(model.constants)
    theta = post.to_theta(z)
    p = {n: theta[:, [j]] for j, n in enumerate(post.names)}

    def fused():
        ft, ok = electroadhesion(p, x, c)
        r = (y - ft["tangential_force"]) / p["sigma"]
        return np.where(ok.all(axis=1), -0.5 * (r * r).sum(axis=1) - y.size * np.log(p["sigma"][:, 0]), -np.inf)

    out = {}
    for name, f in (("skinfit", lambda: post(z)), ("fused", fused)):
        t0 = time.perf_counter()
        for _ in range(repeats):
            f()
        out[name] = repeats * nwalkers / (time.perf_counter() - t0)
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--priors", default=str(HERE / "priors_electroadhesion_uniform.toml"))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--skip-dynesty", action="store_true")
    args = ap.parse_args()
    priors = skinfit.load_priors(args.priors)
    rows = [run_skinfit(priors, args.seed), run_bare_emcee(priors, args.seed)]
    if not args.skip_dynesty:
        rows.append(run_dynesty(priors, args.seed))
    thr = fused_throughput(priors)
    load = os.getloadavg()
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")), platform.processor())
    lines = [f"\n## {time.strftime('%Y-%m-%d %H:%M')} - seed {args.seed}, priors {Path(args.priors).name}\n",
             f"Machine: {os.cpu_count()} CPUs ({cpu}), Python {platform.python_version()}, numpy {np.__version__}, "
             f"emcee {emcee.__version__}; load average at the end {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f}; "
             f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB.\n",
             "| method | wall s | min bulk ESS | max R-hat | ESS/s | evaluations | evals/s | converged |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['method']} | {r['wall_s']:.1f} | {r['min_ess_bulk']:.0f} | {r['max_rhat']:.4f} | "
                     f"{r['min_ess_bulk'] / r['wall_s']:.1f} | {r['evals']} | {r['evals'] / r['wall_s']:.0f} | "
                     f"{r['converged']} |")
    lines.append(f"\nLog-density throughput (32 walkers): skinfit {thr['skinfit']:.0f} evals/s, one fused numpy "
                 f"expression {thr['fused']:.0f} evals/s (ratio {thr['fused'] / thr['skinfit']:.2f}).")
    text = "\n".join(lines) + "\n"
    out = HERE / "results" / "electroadhesion.md"
    out.parent.mkdir(exist_ok=True)
    if not out.exists():
        out.write_text("# Electroadhesion benchmark (bench/bench_electroadhesion.py)\n")
    with out.open("a") as fh:
        fh.write(text)
    print(text)


if __name__ == "__main__":
    main()
