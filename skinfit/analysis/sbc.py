"""Simulation-based calibration (Talts, Betancourt, Simpson, Vehtari & Gelman 2018, arXiv:1804.06788).

For each of ``n_sims`` simulations: draw a parameter vector from the prior, simulate a dataset on
the design (covariates, grouping columns) of a shipped dataset for the model with the model's own
noise model, fit it with :func:`skinfit.fit`, and record the rank of the true value among ``L``
posterior draws.  When the whole pipeline (priors, likelihood, MAP start, emcee, convergence
gate) is calibrated, every parameter's rank is uniform on ``0..L``.

Draws outside the model's physical support are redrawn (the simulation prior is then the prior
restricted to the support, which is also what the fit's posterior uses).  The ``L`` draws are
picked at random from the kept chain; with an effective sample size well above ``L`` they are
close to independent (correlated draws would make the rank histogram U- or hump-shaped).

Uniformity per parameter: a chi-square test on ranks binned into ``B`` equal bins (``B`` divides
``L + 1``; about 5+ expected counts per bin) and a Kolmogorov-Smirnov test on the jittered
normalised ranks ``(rank + U) / (L + 1)``, which are exactly uniform under calibration.  A
parameter passes when the smaller of the two p-values is >= ``alpha`` (1%).  With ``m``
parameters and two tests each, the chance that a calibrated pipeline fails somewhere is at most
``2 m alpha`` (Bonferroni); the ``pass_bonferroni`` column applies the corrected level
``alpha / (2 m)``.
"""

import json
import multiprocessing
import threading
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from skinfit.errors import ConvergenceWarning, InputError, InputTypeError
from skinfit.inference.run import check_sizes, default_walkers
from skinfit.inference.workers import forkable
from skinfit.io.arguments import check_count, check_memory, check_number, shown
from skinfit.io.data import Dataset, list_datasets, load_dataset
from skinfit.io.models import Model, load_model
from skinfit.io.outputs import check_outputs
from skinfit.io.priors import PriorSet, load_priors
from skinfit.posterior import Posterior
from skinfit.results.fitting import fit
from skinfit.results.summary import slot_values

__all__ = ["SBCResult", "run_sbc", "design_dataset", "uniformity", "write_sbc", "markdown_table", "FILES"]


@dataclass(frozen=True)
class SBCResult:
    """Ranks and uniformity tests of one SBC run.

    ``ranks``: DataFrame (n_sims, parameters) of ranks in 0..n_draws; ``truth``: the generating
    values (same shape); ``table``: per parameter chi-square and KS p-values and verdicts;
    ``runs``: per simulation seed, convergence, steps and wall time.
    """

    model: str
    dataset: str
    n_draws: int
    ranks: pd.DataFrame
    truth: pd.DataFrame
    table: pd.DataFrame
    runs: pd.DataFrame
    settings: dict

    @property
    def passed(self):
        return bool(self.table["pass"].all())


def design_dataset(model, dataset=None):
    """The dataset whose design the simulations reuse: ``dataset`` if given, else the first
    shipped dataset made for ``model`` or for a model it competes with (``variants``)."""
    model = model if isinstance(model, Model) else load_model(model)
    if dataset is not None:
        return dataset if isinstance(dataset, Dataset) else load_dataset(dataset)
    family = {model.id, *model.variants}
    for ds_id in list_datasets():
        ds = load_dataset(ds_id)
        if ds.model in family or (ds.model and model.id in load_model(ds.model).variants):
            return ds
    raise InputError(f"model {model.id}", "no shipped dataset for this model or its variants: "
                     "give one with --dataset", field="dataset")


def _rows(ds, n_rows):
    """At most ``n_rows`` rows of ``ds``, evenly spaced (keeps the design's spread)."""
    if n_rows is None or n_rows >= len(ds):
        return ds
    keep = np.zeros(len(ds), dtype=bool)
    keep[np.unique(np.linspace(0, len(ds) - 1, n_rows).round().astype(int))] = True
    return ds.subset(keep, f"{n_rows} rows")


def _slot_draws(fit, names):
    """Posterior draws (n, d) in the order of the sampled slots ``names``."""
    ds = fit.group("posterior")
    slots = {s["name"]: s for s in fit.attr("slots")}
    return np.column_stack([slot_values(ds, slots[n]) for n in names])


def run_sbc(model, dataset=None, *, priors=None, fit_priors=None, n_sims=100, n_draws=99, seed=0,
            n_rows=None, split=None, ess_target=100, max_steps=4000, n_global=300, alpha=0.01,
            jobs=1, progress=None):
    """Simulation-based calibration of ``model``.

    Parameters
    ----------
    model : Model or str
    dataset : Dataset or str, optional
        Design to simulate on (default: :func:`design_dataset`).
    priors : PriorSet or str, optional
        Priors the truths are drawn from (default ``priors/<model>.toml``).
    fit_priors : PriorSet or str, optional
        Priors the fits use (default: ``priors``).  A different prior is a negative control:
        SBC must flag it.
    n_sims : int
        Number of simulated datasets (Talts et al. use 1000; >= 100 for a real check).
    n_draws : int
        ``L``: posterior draws each truth is ranked among (ranks 0..L).
    seed : int
        The one seed: simulation ``i`` uses ``SeedSequence(seed).spawn(n_sims)[i]``.
    n_rows : int, optional
        Use at most this many rows of the design, evenly spaced (cheaper fits).
    ess_target, max_steps, n_global
        Passed to :func:`skinfit.fit` (short fits: SBC needs ``ess_target`` well above ``L/2``).
    alpha : float
        Level of each uniformity test.
    jobs : int
        Simulations run in this many processes; the result does not depend on it (each
        simulation's draws come from its own child seed).
    progress : callable, optional
        Called with a one-line message after each simulation.

    Returns
    -------
    SBCResult
    """
    where = "run_sbc"
    n_sims = check_count(n_sims, where, "n_sims")
    n_draws = check_count(n_draws, where, "n_draws")
    seed = check_count(seed, where, "seed", lo=0)
    n_rows = check_count(n_rows, where, "n_rows", optional=True)
    ess_target = check_number(ess_target, where, "ess_target")
    max_steps = check_count(max_steps, where, "max_steps")
    n_global = check_count(n_global, where, "n_global")
    alpha = check_number(alpha, where, "alpha", hi=1.0)
    jobs = check_count(jobs, where, "jobs")
    if progress is not None and not callable(progress):
        raise InputTypeError(where, f"expected a function of one message, or None (got {shown(progress)})",
                             field="progress")
    model = model if isinstance(model, Model) else load_model(model)
    priors = priors if isinstance(priors, PriorSet) else load_priors(model.id if priors is None else priors)
    fit_priors = priors if fit_priors is None else (
        fit_priors if isinstance(fit_priors, PriorSet) else load_priors(fit_priors))
    design = _rows(design_dataset(model, dataset), n_rows)
    post = Posterior(model, priors, design, split=split)
    names = list(post.names)
    # the simulations' records (a seed, ranks and a row each) and one fit's arrays, before the first is run
    check_memory(n_sims * (len(names) + 64) * 8 * 4, where, "n_sims", f"{n_sims:,} simulations' records",
                 fix="give fewer simulations (n_sims, --n-sims)")
    check_memory(2 * n_draws * len(names) * 8, where, "n_draws", f"{n_draws:,} ranked draws of each simulation",
                 fix="give fewer draws (n_draws, --draws)")
    check_sizes(post, default_walkers(post), max_steps, n_global, 10)
    job = _Job(post, design, fit_priors, split, ess_target, max_steps, n_global, n_draws, seed)
    seeds = np.random.SeedSequence(seed).spawn(n_sims)
    ranks, truths, runs = [], [], []
    for rank, theta, run in _map(job, list(enumerate(seeds)), jobs):
        ranks.append(rank)
        truths.append(theta)
        runs.append(run)
        if progress is not None:
            progress(f"sim {run['sim'] + 1}/{n_sims}: {run['n_steps']} steps, min ESS {run['min_ess']:.0f}, "
                     f"{run['seconds']:.1f} s")
    ranks = pd.DataFrame(ranks, columns=names)
    jitter = np.random.default_rng(np.random.SeedSequence(seed).spawn(n_sims + 1)[-1])
    table = uniformity(ranks, n_draws, alpha=alpha, rng=jitter)
    settings = {"n_sims": n_sims, "n_draws": n_draws, "seed": seed, "n_rows": len(design),
                "ess_target": ess_target, "max_steps": max_steps, "n_global": n_global, "alpha": alpha,
                "priors": priors.id, "fit_priors": fit_priors.id,
                "priors_sha256": priors.sha256, "fit_priors_sha256": fit_priors.sha256}
    return SBCResult(model.id, design.id, n_draws, ranks, pd.DataFrame(truths, columns=names), table,
                     pd.DataFrame(runs), settings)


@dataclass(frozen=True)
class _Job:
    """What one simulation needs (picklable, sent once per worker process)."""

    post: Posterior
    design: Dataset
    fit_priors: PriorSet
    split: object
    ess_target: float
    max_steps: int
    n_global: int
    n_draws: int
    seed: int

    def __call__(self, item):
        i, ss = item
        rng = np.random.default_rng(ss)
        fit_seed = int(rng.integers(2**63 - 1))
        theta = self.post.prior_draw_in_support(rng)
        y = {o: v[0] for o, v in self.post.simulate(theta[None], rng).items()}
        ds = self.design.with_observations(y, f"sbc seed {self.seed} sim {i}")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            result = fit(self.post.model, ds, priors=self.fit_priors, rng=fit_seed, split=self.split,
                         ess_target=self.ess_target, max_steps=self.max_steps, n_global=self.n_global,
                         n_prior_draws=10, complete=False)
        draws = _slot_draws(result, list(self.post.names))
        pick = rng.choice(len(draws), size=self.n_draws, replace=len(draws) < self.n_draws)
        s = result.attr("sampler")
        run = {"sim": i, "fit_seed": fit_seed, "converged": s["converged"], "n_steps": s["n_steps"],
               "min_ess": min(s["ess_emcee"].values()), "seconds": result.attr("timings")["total_s"],
               "warning": "; ".join(str(w.message) for w in caught if w.category is ConvergenceWarning)}
        return (draws[pick] < theta).sum(axis=0), theta, run


_JOB = None


def _init_worker(job):
    global _JOB
    _JOB = job


def _run_one(item):
    return _JOB(item)


def _map(job, items, jobs):
    """``job`` over ``items`` in order, in ``jobs`` processes (forked: no re-import per task),
    never forked from a process with other threads (:func:`skinfit.inference.workers.forkable`): there
    one at a time in this process, with a warning."""
    if jobs is None or jobs <= 1 or len(items) <= 1:
        yield from map(job, items)
        return
    if not forkable():
        why = (f"this process runs {threading.active_count() - 1} other thread(s) (a notebook kernel, a Dask client, "
               "...) and forking it could deadlock the workers" if "fork" in multiprocessing.get_all_start_methods()
               else "this platform cannot fork workers")
        warnings.warn(f"SBC: {why}: the {len(items)} simulations run here one at a time (run `skinfit sbc --jobs N` "
                      "from a shell for parallel ones)", UserWarning, stacklevel=3)
        yield from map(job, items)
        return
    ctx = multiprocessing.get_context("fork")
    with ProcessPoolExecutor(min(jobs, len(items)), mp_context=ctx, initializer=_init_worker,
                             initargs=(job,)) as pool:
        yield from pool.map(_run_one, items)


def n_bins(n_sims, n_draws, min_expected=5):
    """Largest divisor of ``n_draws + 1`` giving at least ``min_expected`` ranks per bin (>= 2)."""
    best = 2 if (n_draws + 1) % 2 == 0 else 1
    for b in range(2, n_draws + 2):
        if (n_draws + 1) % b == 0 and n_sims / b >= min_expected:
            best = b
    return best


def uniformity(ranks, n_draws, *, alpha=0.01, rng=None):
    """Per column of ``ranks`` (integers in 0..n_draws): chi-square and KS p-values and verdicts.

    Returns a DataFrame indexed by parameter with columns ``mean_rank`` (expected n_draws/2),
    ``bins``, ``p_chi2``, ``p_ks``, ``p_min``, ``pass`` (p_min >= alpha) and ``pass_bonferroni``
    (p_min >= alpha / (2 * number of parameters)).
    """
    rng = np.random.default_rng(0) if rng is None else rng
    ranks = pd.DataFrame(ranks)
    n, m = ranks.shape
    b = n_bins(n, n_draws)
    rows = {}
    for name in ranks.columns:
        r = ranks[name].to_numpy(dtype=int)
        if r.min() < 0 or r.max() > n_draws:
            raise ValueError(f"ranks of {name} outside 0..{n_draws}")
        counts = np.bincount(r * b // (n_draws + 1), minlength=b)
        p_chi2 = float(stats.chisquare(counts).pvalue) if b > 1 else float("nan")
        u = (r + rng.uniform(size=n)) / (n_draws + 1)
        p_ks = float(stats.kstest(u, "uniform").pvalue)
        p_min = float(np.nanmin([p_chi2, p_ks]))
        rows[name] = {"mean_rank": float(r.mean()), "bins": b, "p_chi2": p_chi2, "p_ks": p_ks,
                      "p_min": p_min, "pass": p_min >= alpha, "pass_bonferroni": p_min >= alpha / (2 * m)}
    return pd.DataFrame.from_dict(rows, orient="index")


def markdown_table(result):
    """The per-parameter table as Markdown, with the run's size and verdict."""
    lines = [f"| parameter | mean rank (expect {result.n_draws / 2:.1f}) | bins | p chi2 | p KS | pass 1% "
             "| pass Bonferroni |", "|---|---|---|---|---|---|---|"]
    for name, r in result.table.iterrows():
        lines.append(f"| {name} | {r['mean_rank']:.1f} | {r['bins']} | {r['p_chi2']:.3g} | {r['p_ks']:.3g} | "
                     f"{'yes' if r['pass'] else 'NO'} | {'yes' if r['pass_bonferroni'] else 'NO'} |")
    return "\n".join(lines)


#: The files ``skinfit sbc --out`` writes: :func:`write_sbc`'s tables and the rank histograms
#: (``ranks.png``, :func:`skinfit.plots.sbc.plot_ranks`).
FILES = ("ranks.csv", "truth.csv", "sbc.csv", "runs.csv", "sbc.json", "sbc.md", "ranks.png")


def write_sbc(result, out, *, overwrite=False):
    """Write ``ranks.csv``, ``truth.csv``, ``sbc.csv`` (tests), ``runs.csv``, ``sbc.md`` and
    ``sbc.json`` under ``out``; a folder holding an earlier run's files (:data:`FILES`) is
    refused unless ``overwrite``.  The rank histograms are :func:`skinfit.plots.sbc.plot_ranks`'."""
    check_outputs(out, FILES, command="skinfit sbc", overwrite=overwrite)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    result.ranks.to_csv(out / "ranks.csv", index_label="sim")
    result.truth.to_csv(out / "truth.csv", index_label="sim")
    result.table.to_csv(out / "sbc.csv", index_label="parameter")
    result.runs.to_csv(out / "runs.csv", index=False)
    (out / "sbc.json").write_text(json.dumps({"model": result.model, "dataset": result.dataset,
                                              "passed": result.passed, **result.settings}, indent=2))
    (out / "sbc.md").write_text(f"# SBC: {result.model} on the design of {result.dataset}\n\n"
                                f"{len(result.ranks)} simulations, L = {result.n_draws} draws each; "
                                f"settings {json.dumps(result.settings)}\n\n{markdown_table(result)}\n")
    return out
