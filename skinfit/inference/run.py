"""One fit's inference: the inputs resolved and checked, the MAP, the importance start and emcee
until converged.

:func:`run` returns plain objects (the :class:`~skinfit.posterior.Posterior`, the
:class:`~skinfit.inference.sampling.SamplerRun`, the MAP, the guard rails' findings), from which
:func:`skinfit.fit` builds the result (:mod:`skinfit.results`). Sizes are checked against the
memory available before any work starts (:func:`check_sizes`, :func:`memory_budget`), and the
pointwise groups a result computes from the draws are thinned to fit it
(:func:`pointwise_thinning`).
"""

from __future__ import annotations

import math
import os
import time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from skinfit.errors import InputError
from skinfit.inference.checkpoint import Checkpoint, load_checkpoint, run_identity
from skinfit.inference.guardrails import assess_run
from skinfit.inference.misfit import RawSeriesWarning, raw_series
from skinfit.inference.optimize import MAPResult, find_map, laplace_covariance
from skinfit.inference.proposal import MixtureT
from skinfit.inference.sampling import (
    CHECK_EVERY,
    SamplerRun,
    importance_start,
    initial_ball,
    run_emcee,
    sampler_settings,
)
from skinfit.io.arguments import (
    as_generator,
    available_memory,
    check_count,
    check_flag,
    check_mapping,
    check_memory,
    check_output_file,
    check_path,
)
from skinfit.io.data import Dataset, as_dataset
from skinfit.io.models import Model, load_model
from skinfit.io.priors import PriorSet, list_priors, load_priors
from skinfit.io.provenance import input_record, warn_shadows
from skinfit.io.user_priors import as_prior_set
from skinfit.posterior import Posterior

__all__ = ["Run", "run", "resolve_inputs", "start", "default_walkers", "check_sizes", "memory_budget",
           "pointwise_thinning", "pointwise_bytes", "MEMORY_FRACTION"]

#: Share of the available memory (:func:`~skinfit.io.arguments.available_memory`) the pointwise
#: log-likelihood and predictive groups of a result may take while they are built: 2 groups x
#: observables x draws x rows float64, counted twice (the arrays and the tree's copy; a save adds
#: the file's image, about one copy more).  Over it, :func:`pointwise_thinning` keeps every k-th
#: draw of each walker in them, and when one draw per walker is still over it, one draw of every
#: j-th walker (the posterior group keeps every draw); when a single draw is over it, :func:`run`
#: refuses before the MAP.
MEMORY_FRACTION = 0.25


@dataclass(frozen=True)
class Run:
    """What one fit's inference gives.

    ``posterior`` the :class:`~skinfit.posterior.Posterior` sampled; ``sampler`` its
    :class:`~skinfit.inference.sampling.SamplerRun` (kept chain in sampling coordinates);
    ``map`` the :class:`~skinfit.inference.optimize.MAPResult`; ``importance`` the importance
    rounds of the start; ``rng`` the Generator, advanced past the sampling (the result's prior
    and predictive draws come next from it); ``seed`` the integer seed (None for a Generator
    passed in) and ``seed_drawn`` whether it was drawn because none was given; ``inputs`` the
    record of the files read (:func:`skinfit.io.provenance.input_record`); ``warnings`` and
    ``notes`` the guard rails' findings (:func:`skinfit.inference.guardrails.assess_run`);
    ``timings`` [s]: ``map_s``, ``start_s`` (MAP and importance start; 0 when resumed),
    ``sampling_s`` and ``resumed``.
    """

    posterior: Posterior
    sampler: SamplerRun
    map: MAPResult
    importance: tuple
    rng: np.random.Generator
    seed: int | None
    seed_drawn: bool
    inputs: dict
    warnings: list
    notes: list
    timings: dict


def run(model: str | Model, dataset: str | os.PathLike | Dataset | pd.DataFrame,
        priors: str | os.PathLike | PriorSet | None = None, *, units: Mapping[str, str] | None = None,
        columns: Mapping[str, str] | None = None, rng: int | np.random.Generator | None = None,
        split: Mapping[str, Sequence[str]] | None = None,
        noise: str | Mapping[str, str] | None = None, constants: Mapping[str, float] | None = None,
        nwalkers: int | None = None, ess_target: float = 400, max_steps: int = 20000, progress: bool = False,
        n_global: int = 2000, n_local: int = 4, n_prior_draws: int = 2000,
        checkpoint: str | os.PathLike | None = None, resume: bool = False,
        checkpoint_every: float = 30.0) -> Run:
    """MAP by nlopt, the importance start, then emcee until converged (the arguments are
    :func:`skinfit.fit`'s, which documents them; ``n_prior_draws`` is checked against the memory
    here and drawn by the caller).

    Every argument is checked and the inputs resolved before any work starts; the files read
    are recorded and any they hide warned about (:class:`~skinfit.io.provenance.ShadowWarning`).
    Draws from ``rng`` in a fixed order: the MAP's prior draws, the importance draws, the
    walkers, the sampling.
    """
    _check_settings(rng, max_steps=max_steps, ess_target=ess_target, nwalkers=nwalkers,
                    checkpoint_every=checkpoint_every)
    n_global = check_count(n_global, "fit", "n_global")
    # searches from at most every prior draw; the default 4 stays valid when n_global is smaller
    n_local = min(check_count(n_local, "fit", "n_local", lo=0, hi=max(n_global, 4)), n_global)
    n_prior_draws = check_count(n_prior_draws, "fit", "n_prior_draws")
    progress, resume = (check_flag(v, "fit", k) for k, v in (("progress", progress), ("resume", resume)))
    if checkpoint is not None:
        checkpoint = check_output_file(checkpoint, "fit", "checkpoint", "checkpoint")
    check_mapping(units, "fit", "units", "a mapping column -> unit")
    check_mapping(columns, "fit", "columns", "a mapping header -> skinfit name")
    model, dataset, priors = resolve_inputs(model, dataset, priors, units=units, columns=columns)
    inputs = input_record(model, priors, dataset)  # the files read, and any they hid: said now, not after sampling
    warn_shadows(inputs, model, priors)
    seed_drawn = rng is None
    if seed_drawn and resume and checkpoint is not None and Path(checkpoint).exists():
        rng = load_checkpoint(checkpoint).meta.get("seed")  # the seed drawn by the interrupted run
    if rng is None:  # no seed given: draw one and record it, so the fit can be repeated exactly
        rng = int(np.random.SeedSequence().entropy % 2**63)
    seed = rng if isinstance(rng, (int, np.integer)) else None
    rng = as_generator(rng)
    post = Posterior(model, priors, dataset, split=split, noise=noise, constants=constants)
    raw = raw_series(dataset)  # a raw recording fitted by mistake: said now, before the sampling it would waste
    if raw:
        warnings.warn(f"{model.id} on {dataset.id}: {raw}", RawSeriesWarning, stacklevel=3)

    if nwalkers is not None and nwalkers < 2 * post.ndim:  # emcee's ensemble moves need it
        raise InputError("fit", f"expected at least 2 walkers per sampled parameter, {2 * post.ndim} for the "
                                f"{post.ndim} of this fit (got {nwalkers}; default {default_walkers(post)})",
                         field="nwalkers")
    nwalkers = nwalkers or default_walkers(post)
    memory_budget(post)  # refuse now, not after sampling, data too large to complete
    check_sizes(post, nwalkers, max_steps, n_global, n_prior_draws)
    ckpt, saved = None, None
    if checkpoint is not None:
        settings = {"ess_target": ess_target, "max_steps": max_steps, "n_global": n_global,
                    "n_local": n_local, "n_prior_draws": n_prior_draws, "sampler": sampler_settings()}
        ckpt = Checkpoint(checkpoint, run_identity(post, seed=seed, nwalkers=nwalkers, settings=settings),
                          interval=checkpoint_every)
        if resume and Path(checkpoint).exists():
            saved = load_checkpoint(checkpoint)
            saved.verify(ckpt.identity)
    t_begin = time.perf_counter()
    if saved is None:
        map_result, proposal, p0, rounds = start(post, rng, nwalkers=nwalkers, n_global=n_global, n_local=n_local)
    else:
        map_result, proposal, p0 = MAPResult.from_record(saved.map), MixtureT.from_dict(saved.proposal), saved.p0
        rounds = saved.importance
        rng.bit_generator.state = saved.generator_state
    t_start_s = time.perf_counter() - t_begin
    if ckpt is not None:
        ckpt.start(p0, rng.bit_generator.state, map_result, proposal, rounds)
    sampler = run_emcee(post, p0, rng, ess_target=ess_target, max_steps=max_steps, progress=progress,
                        checkpoint=ckpt, resume=saved, proposal=proposal, check_every=CHECK_EVERY,
                        natural=post.to_theta)
    found, notes = assess_run(post, sampler)
    if raw:  # recorded with the guard rails' findings (warned above)
        found = [{"check": "raw_series", "status": "WARN", "parameter": None, "message": raw}, *found]
    return Run(posterior=post, sampler=sampler, map=map_result, importance=tuple(rounds), rng=rng, seed=seed,
               seed_drawn=seed_drawn, inputs=inputs, warnings=found, notes=notes,
               timings={"map_s": map_result.seconds, "start_s": t_start_s if saved is None else 0.0,
                        "sampling_s": sampler.seconds, "resumed": saved is not None})


def resolve_inputs(model, dataset, priors=None, *, units=None, columns=None):
    """The Model, Dataset and PriorSet :func:`run` fits, from what it accepts: ids, paths or
    loaded objects; the priors default to the model's prior file. Loaded objects pass through,
    so a caller that resolves them first (to check them) loads nothing twice; a mapping of priors
    given in Python becomes a PriorSet (:func:`skinfit.io.user_priors.as_prior_set`)."""
    model = model if isinstance(model, Model) else load_model(model)
    dataset = as_dataset(dataset, model=model, units=units, columns=columns)
    if isinstance(priors, Mapping):
        return model, dataset, as_prior_set(priors, model)
    if not (priors is None or isinstance(priors, PriorSet)):
        check_path(priors, "priors", None, "a PriorSet, a mapping parameter -> scipy.stats distribution, a prior "
                                           "file id or the path of a prior file")
    if priors is None and model.function is not None and model.id not in list_priors():
        raise InputError("fit", f"model {model.id!r} was made from a Python function and has no prior file: pass "
                                "priors={name: scipy.stats distribution} (sigma for the noise too)", field="priors")
    priors = priors if isinstance(priors, PriorSet) else load_priors(model.id if priors is None else priors)
    return model, dataset, priors


def _check_settings(rng, **settings):
    """InputError for a seed numpy refuses or a fit cannot record (< 0 or >= 2**63) and for
    step counts, ESS targets and intervals that are not positive (or not finite)."""
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool) and not 0 <= int(rng) < 2**63:
        raise InputError("fit", f"expected a seed 0 .. 2**63-1 (got {int(rng)})", field="rng")
    for name, value in settings.items():
        if value is None and name == "nwalkers":
            continue
        integer = name in ("max_steps", "nwalkers")
        ok = (isinstance(value, (int, np.integer)) and not isinstance(value, bool) if integer
              else isinstance(value, (int, float, np.number)) and not isinstance(value, bool))
        if not ok or not (0 < value < float("inf")):
            raise InputError("fit", f"expected {'a whole number' if integer else 'a finite number'} > 0 "
                                    f"(got {value!r})", field=name)


def check_sizes(post, nwalkers, max_steps, n_global, n_prior_draws):
    """Refuse counts whose arrays would not fit in the memory available now: the chain if it runs
    to ``max_steps`` (emcee keeps every step of every walker, and doubles the array while it
    grows it), the ``n_global`` prior draws of the MAP search and the ``n_prior_draws`` of the
    prior group, all float64 (InputError with the estimate, before the MAP)."""
    where = f"fit of {post.model.id} on {post.dataset.id}"
    d, available = post.ndim, available_memory()
    per_step = 2 * nwalkers * (d + 2) * 8
    check_memory(per_step, where, "nwalkers", f"one step of {nwalkers:,} walkers x {d} parameters",
                 fix="give fewer walkers", available=available)
    check_memory(per_step * max_steps, where, "max_steps", f"a chain of {max_steps:,} steps x {nwalkers:,} walkers x "
                 f"{d} parameters", fix=f"give max_steps (--max-steps) at most {max(1, int(available // per_step)):,}",
                 available=available)
    check_memory(6 * n_global * (d + 1) * 8, where, "n_global", f"scoring {n_global:,} prior draws",
                 fix="give a smaller n_global", available=available)
    check_memory(2 * n_prior_draws * (d + 1) * 8, where, "n_prior_draws", f"{n_prior_draws:,} prior draws",
                 fix="give a smaller n_prior_draws", available=available)


def start(post, rng, *, nwalkers, n_global=2000, n_local=4):
    """Where :func:`run` starts sampling: (MAP, proposal, walkers, importance rounds).

    The MAP (:func:`~skinfit.inference.optimize.find_map`); the Laplace approximation there in
    sampling coordinates as a Student-t, improved by importance sampling into the first
    independence proposal, with ``nwalkers`` walkers drawn from the weighted draws
    (:func:`~skinfit.inference.sampling.importance_start`); when the importance weights are
    degenerate, the Laplace proposal and walkers drawn around the MAP.  Draws from ``rng`` in
    this order: the MAP's prior draws, the importance draws, then the walkers.
    """
    map_result = find_map(post, rng, n_global=n_global, n_local=n_local)
    z_map = post.to_z(map_result.theta[None])[0]
    cov = laplace_covariance(post, z_map)
    laplace = MixtureT.with_wide_half(z_map, cov)
    proposal, p0, rounds = importance_start(post, laplace, nwalkers, rng)
    if p0 is None:
        p0 = initial_ball(post, z_map, cov, nwalkers, rng)
    return map_result, proposal, p0, rounds


def default_walkers(post):
    """Walkers of a fit: at least 32, and at least four per sampled dimension (even)."""
    return max(32, 2 * ((4 * post.ndim + 1) // 2))


def pointwise_bytes(n_obs, n_rows, n_draws):
    """Peak bytes of the pointwise groups for ``n_draws`` draws (see :data:`MEMORY_FRACTION`)."""
    return 2 * 2 * 8 * n_obs * n_rows * n_draws


def _ordinal(k):
    return f"{k}{'th' if 10 <= k % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(k % 10, 'th')}"


def memory_budget(post):
    """(bytes one draw of the pointwise groups takes, the budget): InputError when a single draw
    is over the budget (checked by :func:`run` before the MAP, and when the groups are built)."""
    available = available_memory()
    budget = MEMORY_FRACTION * available
    per_draw = pointwise_bytes(len(post.observables), post.n, 1)
    if per_draw > budget:
        raise InputError(f"fit of {post.model.id} on {post.dataset.id}",
                         f"one posterior draw's pointwise log-likelihood and predictive values would need "
                         f"{_size(per_draw)} ({post.n} rows x {len(post.observables)} observable(s)), over "
                         f"{MEMORY_FRACTION:.0%} of the available memory ({_size(available)}): fit a subset of "
                         "the rows (e.g. --by a grouping column)")
    return per_draw, budget


def _size(nbytes):
    return f"{nbytes / 2**30:.1f} GiB" if nbytes >= 2**30 else f"{nbytes / 2**20:.1f} MiB"


def pointwise_thinning(post, nwalkers, ndraws):
    """(every, walker_step, note): the draws of the pointwise groups of ``nwalkers`` x ``ndraws``
    posterior draws that fit the memory budget (:data:`MEMORY_FRACTION`): every draw (1, 1,
    None), every ``every``-th draw of each walker, or one draw of every ``walker_step``-th
    walker, with a note saying which."""
    per_draw, budget = memory_budget(post)
    nw, nd = nwalkers, ndraws
    total = per_draw * nw * nd
    if total <= budget:
        return 1, 1, None
    fits = int(budget // per_draw)  # draws within the budget (>= 1, see memory_budget)
    if fits >= nw:
        every, walker_step = math.ceil(nd / (fits // nw)), 1
        which = f"every {_ordinal(every)} draw of each walker"
    else:
        every, walker_step = nd, math.ceil(nw / fits)
        which = f"one draw of every {_ordinal(walker_step)} walker"
    kept = len(range(0, nw, walker_step)) * len(range(0, nd, every))
    note = (f"pointwise log-likelihood and predictive draws on {which} ({kept} of {nw * nd}): all draws would "
            f"need {_size(total)}, over {MEMORY_FRACTION:.0%} of the available memory "
            f"({_size(budget / MEMORY_FRACTION)})")
    return every, walker_step, note
