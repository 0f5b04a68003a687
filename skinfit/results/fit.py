"""``skinfit.fit``: MAP (nlopt) -> emcee from the Laplace ball -> diagnostics -> a Fit.

A :class:`Fit` wraps one ArviZ DataTree (groups posterior, prior, sample_stats, log_likelihood,
posterior_predictive, observed_data, constant_data, derived) whose root attributes record where
every number came from: model card, prior file and dataset (with hashes and full texts),
skinfit and dependency versions, seed, MAP, optimiser status, timings and convergence.  The
pointwise ``log_likelihood`` and ``posterior_predictive`` groups, (draws x rows) each and most
of the tree's cost, are computed on first use (:attr:`Fit.idata`, :meth:`Fit.save`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # names used only in annotations
    from collections.abc import Sequence

import errno
import json
import math
import os
import shutil
import sys
import time
import warnings
from collections.abc import Iterable, Mapping
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from functools import lru_cache
from importlib import metadata
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

from skinfit.results._xarray import defer_imports
from skinfit.io.data import Dataset, as_dataset
from skinfit.io.labels import annotate
from skinfit.io.units import si_unit
from skinfit.io.arguments import (available_memory as _available_memory, check_count, check_flag, check_input_file,
                        check_mapping, check_memory, check_output_file, check_path, check_seed, shown)
from skinfit.errors import ConvergenceWarning, InputError, InputTypeError
from skinfit.io.models import Model, load_model
from skinfit.inference.guardrails import assess_run
from skinfit.io.provenance import input_lines, input_record, inputs_of, warn_shadows
from skinfit.io import integrity

__all__ = ["fit", "Fit", "load_fit", "as_generator", "resolve_inputs"]

defer_imports()


def _fitting():
    """Import what fitting needs into this module (once): the optimiser, sampler, posterior,
    priors and ArviZ's tree builder (scipy.stats, emcee, nlopt, arviz_base: ~1.5-2 s), which
    reading and reporting a saved fit do without.  A name already set (a test's stand-in for
    ``find_map``) is kept.  Called first thing by :func:`fit`: importing arviz_base walks the
    call stack (lazy_loader's look-up of numpyro), which took 0.4 s from deep inside a fit
    against 0.06 s near the top."""
    g = globals()
    if "run_emcee" in g:
        return
    from arviz_base import from_dict
    from skinfit.inference.optimize import find_map, laplace_covariance
    from skinfit.posterior import Posterior, _level_labels
    from skinfit.io.priors import PriorSet, load_priors
    from skinfit.inference.proposal import MixtureT
    from skinfit.inference.sampling import CHECK_EVERY, describe_moves, importance_start, initial_ball, run_emcee, sampler_settings

    imported = locals()
    for name in _FITTING_NAMES:
        g.setdefault(name, imported[name])


#: The names :func:`_fitting` imports (a name listed but not imported there fails every fit).
_FITTING_NAMES = ("from_dict", "find_map", "laplace_covariance", "Posterior", "_level_labels", "PriorSet",
                  "load_priors", "MixtureT", "CHECK_EVERY", "describe_moves", "importance_start", "initial_ball",
                  "run_emcee", "sampler_settings")


def __getattr__(name):
    """The names of :func:`_fitting` as attributes of this module, imported on first use."""
    if name not in _FITTING_NAMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    _fitting()
    return globals()[name]

#: The groups of a fit's tree in ArviZ's order; the two of :data:`DEFERRED` are computed on
#: first use.
GROUPS = ("posterior", "prior", "sample_stats", "log_likelihood", "posterior_predictive", "observed_data",
          "constant_data", "derived")
DEFERRED = ("log_likelihood", "posterior_predictive")

_VERSIONED = ("skinfit", "numpy", "scipy", "emcee", "nlopt", "arviz", "arviz-base", "arviz-stats",
              "xarray", "pandas")


def as_generator(rng, where="rng"):
    """SPEC 7: an int seed >= 0, None or a numpy Generator -> a numpy Generator (InputTypeError,
    a TypeError, for anything else: a float, a bool, a string)."""
    if isinstance(rng, np.random.Generator):
        return rng
    return np.random.default_rng(check_seed(rng, where, None))


def fit(model: str | Model, dataset: str | os.PathLike | Dataset | pd.DataFrame,
        priors: str | os.PathLike | PriorSet | None = None, *, units: Mapping[str, str] | None = None,
        rng: int | np.random.Generator | None = None, split: Mapping[str, Sequence[str]] | None = None,
        noise: str | Mapping[str, str] | None = None, constants: Mapping[str, float] | None = None,
        nwalkers: int | None = None, ess_target: float = 400, max_steps: int = 20000, progress: bool = False,
        strict: bool = False, n_global: int = 2000, n_local: int = 4, n_prior_draws: int = 2000,
        checkpoint: str | os.PathLike | None = None, resume: bool = False,
        checkpoint_every: float = 30.0) -> Fit:
    """Fit ``model`` to ``dataset``: MAP by nlopt, then emcee until converged.

    Parameters
    ----------
    model : Model or str
        A model or a model id (``models/<id>.toml``).
    dataset : Dataset, pandas.DataFrame or str
        A dataset, a dataset id / card path, a CSV path with units in its header
        (``normal_force [mN]``), or a DataFrame (:func:`skinfit.io.data.from_frame`).
    units : mapping column -> unit, optional
        Units of DataFrame or CSV columns whose name does not carry one (``{"voltage": "V"}``).
    priors : PriorSet or str, optional
        Default: ``priors/<model id>.toml``.
    rng : int, None or numpy.random.Generator
        The one source of randomness (SPEC 7); the same seed gives identical samples.  The fit
        draws from it in a fixed order (MAP search, importance start, walkers, sampling, prior
        draws) and last the seed of a child generator kept for the posterior-predictive draws:
        the same seed gives identical ``log_likelihood`` and ``posterior_predictive`` groups
        whenever they are computed, and a Generator passed in is advanced by the fit alone.
    split : mapping parameter -> column(s), optional
        Parameters fitted once per level of a grouping column (default: the card's ``[split]``).
    noise : str or mapping observable -> str, optional
        ``normal`` (default), ``student_t`` or ``lognormal``.
    ess_target : float
        Minimum effective sample size per parameter to call the run converged.
    n_global, n_local : int
        MAP search: prior draws scored in one vectorised call, then SLSQP from the ``n_local``
        best of them and a BOBYQA polish (:func:`~skinfit.inference.optimize.find_map`; measurements in
        docs/design/sampling.md).
    strict : bool
        Raise instead of warn when the run does not meet its convergence criteria.
    checkpoint : path-like, optional
        Checkpoint file written while sampling (every ``checkpoint_every`` seconds, at the end
        and on KeyboardInterrupt); see :mod:`skinfit.inference.checkpoint`.
    resume : bool
        Continue from ``checkpoint`` if it exists (MAP, walkers and random states restored:
        the result equals an uninterrupted run's); InputError if it belongs to other inputs.

    Returns
    -------
    Fit
        Its tree holds every group but ``log_likelihood`` and ``posterior_predictive`` (a
        value per posterior draw and data row each), which are computed on first use of
        :attr:`Fit.idata` (or by :meth:`Fit.save`, ``skinfit fit``, reports and
        :func:`~skinfit.compare`); until then :attr:`Fit.pending` is true.  Its
        ``attr("timings")`` [s]: ``map_s`` the MAP search;
        ``start_s`` from the first random draw to the first step (the MAP search and the
        importance start); ``sampling_s``; ``tree_s`` the result tree without the deferred
        groups; ``total_s`` the whole call; ``resumed``; and, once they are computed,
        ``pointwise_s`` the deferred groups.  A resumed fit (``resumed`` true) had its MAP and
        start in the run that wrote the checkpoint: its ``map_s`` is that run's, ``start_s``
        is 0 and ``sampling_s`` sums every run's sampling.
    """
    t_start = time.perf_counter()
    _fitting()
    _check_settings(rng, max_steps=max_steps, ess_target=ess_target, nwalkers=nwalkers,
                    checkpoint_every=checkpoint_every)
    n_global = check_count(n_global, "fit", "n_global")
    n_local = min(check_count(n_local, "fit", "n_local", lo=0), n_global)  # local searches from the best prior draws: at most all of them
    n_prior_draws = check_count(n_prior_draws, "fit", "n_prior_draws")
    progress, strict, resume = (check_flag(v, "fit", k) for k, v in
                                (("progress", progress), ("strict", strict), ("resume", resume)))
    if checkpoint is not None:
        checkpoint = check_output_file(checkpoint, "fit", "checkpoint", "checkpoint")
    check_mapping(units, "fit", "units", "a mapping column -> unit")
    model, dataset, priors = resolve_inputs(model, dataset, priors, units=units)
    inputs = input_record(model, priors, dataset)  # the files read, and any they hid: said now, not after sampling
    warn_shadows(inputs, model, priors)
    seed_drawn = rng is None
    if seed_drawn and resume and checkpoint is not None and Path(checkpoint).exists():
        from skinfit.inference.checkpoint import load_checkpoint

        rng = load_checkpoint(checkpoint).meta.get("seed")  # the seed drawn by the interrupted run
    if rng is None:  # no seed given: draw one and record it, so the fit can be repeated exactly
        rng = int(np.random.SeedSequence().entropy % 2**63)
    seed = rng if isinstance(rng, (int, np.integer)) else None
    rng = as_generator(rng)
    post = Posterior(model, priors, dataset, split=split, noise=noise, constants=constants)

    if nwalkers is not None and nwalkers < 2 * post.ndim:  # emcee's ensemble moves need it
        raise InputError("fit", f"expected at least 2 walkers per sampled parameter, {2 * post.ndim} for the "
                                f"{post.ndim} of this fit (got {nwalkers}; default {default_walkers(post)})",
                         field="nwalkers")
    nwalkers = nwalkers or default_walkers(post)
    _memory_budget(post)  # refuse now, not after sampling, data too large to complete
    check_sizes(post, nwalkers, max_steps, n_global, n_prior_draws)
    ckpt, saved = None, None
    if checkpoint is not None:
        from skinfit.inference.checkpoint import Checkpoint, load_checkpoint, map_from_record, run_identity

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
        map_result, proposal, p0 = map_from_record(saved.map), MixtureT.from_dict(saved.proposal), saved.p0
        rounds = saved.importance
        rng.bit_generator.state = saved.generator_state
    t_start_s = time.perf_counter() - t_begin
    if ckpt is not None:
        ckpt.start(p0, rng.bit_generator.state, map_result, proposal, rounds)
    run = run_emcee(post, p0, rng, ess_target=ess_target, max_steps=max_steps, progress=progress,
                    checkpoint=ckpt, resume=saved, proposal=proposal, check_every=CHECK_EVERY,
                    natural=post.to_theta)
    if not run.converged:
        msg = f"{model.id} on {dataset.id}: not converged after {run.n_steps} steps: " + "; ".join(run.reasons)
        if strict:
            raise RuntimeError(msg)
        warnings.warn(msg, ConvergenceWarning, stacklevel=2)
    t_tree = time.perf_counter()
    idata, deferred = _build_tree(post, run, map_result, rng, n_prior_draws, seed=seed, importance=rounds)
    idata.attrs["seed_drawn"] = int(seed_drawn)
    idata.attrs["inputs"] = json.dumps(inputs)
    now = time.perf_counter()
    idata.attrs["timings"] = json.dumps({"map_s": map_result.seconds,
                                         "start_s": t_start_s if saved is None else 0.0,
                                         "sampling_s": run.seconds, "tree_s": now - t_tree, "total_s": now - t_start,
                                         "resumed": saved is not None})
    for w in json.loads(idata.attrs["warnings"]):  # non-convergence was warned above
        if w["check"] != "convergence":
            warnings.warn(f"{model.id} on {dataset.id}: {w['message']}", ConvergenceWarning, stacklevel=2)
    return Fit(idata, posterior=post, deferred=deferred)


def resolve_inputs(model, dataset, priors=None, *, units=None):
    """The Model, Dataset and PriorSet :func:`fit` fits, from what it accepts: ids, paths or
    loaded objects; the priors default to the model's prior file. Loaded objects pass through,
    so a caller that resolves them first (to check them) loads nothing twice."""
    _fitting()  # PriorSet and load_priors
    model = model if isinstance(model, Model) else load_model(model)
    dataset = as_dataset(dataset, model=model, units=units)
    if not (priors is None or isinstance(priors, PriorSet)):
        check_path(priors, "priors", None, "a PriorSet, a prior file id or the path of a prior file")
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
    """Where :func:`fit` starts sampling: (MAP, proposal, walkers, importance rounds).

    The MAP (:func:`~skinfit.inference.optimize.find_map`); the Laplace approximation there in sampling
    coordinates as a Student-t, improved by importance sampling into the first independence
    proposal, with ``nwalkers`` walkers drawn from the weighted draws
    (:func:`~skinfit.inference.sampling.importance_start`); when the importance weights are degenerate,
    the Laplace proposal and walkers drawn around the MAP.  Draws from ``rng`` in this order:
    the MAP's prior draws, the importance draws, then the walkers.
    """
    _fitting()
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


def _build_tree(post, run, map_result, rng, n_prior_draws, *, seed, importance=()):
    """The result tree without the groups of :data:`DEFERRED`, and what computes them later."""
    nw, nd, d = run.chain.shape
    theta = post.to_theta(run.chain.reshape(-1, d))
    t_prior = post.sample_prior(n_prior_draws, rng)
    # after the prior draws, the last draw of a fit: the predictive draws' own generator
    deferred = _Deferred(theta, nw, nd, rng.integers(2**63, size=4))
    # the chain's own log density, less the sampling map's Jacobian: log prior + log likelihood in
    # natural parameters with no further forward call (wavy_surface, 4000 draws: 0.2 s)
    lp_nat = run.log_prob.reshape(-1) - post.log_jacobian(run.chain.reshape(-1, d))
    posterior, prior_group, dims, coords = {}, {}, {}, {"obs_id": np.arange(post.n)}
    for pname in list(post.model.parameter_names) + list(post.noise_names):
        cols = [j for j, s in enumerate(post.slots) if s.base == pname]
        if pname in post.levels:
            dim = ",".join(post.levels[pname][0])
            coords[dim] = list(post.levels[pname][1])
            dims[pname] = [dim]
            posterior[pname] = theta[:, cols].reshape(nw, nd, len(cols))
            prior_group[pname] = t_prior[:, cols].reshape(1, n_prior_draws, len(cols))
        else:
            posterior[pname] = theta[:, cols[0]].reshape(nw, nd)
            prior_group[pname] = t_prior[:, cols[0]].reshape(1, n_prior_draws)
    dims.update({o: ["obs_id"] for o in post.observables})
    constant = {c: np.asarray(v) for c, v in post.x.items()}
    for c in post.dataset.frame.columns:
        if c not in constant and c not in post.observables:
            col = post.dataset.frame[c]
            constant[c] = col.to_numpy(dtype=object if col.dtype == object or str(col.dtype).startswith("str") else float)
    for c in constant:
        dims[c] = ["obs_id"]
    ds = post.dataset
    attrs = {
        "skinfit_schema": integrity.CHECKED_SCHEMA,  # saved with checksums (skinfit.io.integrity)
        "model_id": post.model.id, "model_sha256": post.model.sha256, "model_card": post.model.card_text,
        "priors_id": post.priors.id, "priors_sha256": post.priors.sha256, "priors_text": post.priors.text,
        "dataset_id": ds.id, "dataset_sha256": ds.sha256, "dataset_path": ds.path,
        "dataset_provenance": json.dumps(dict(ds.provenance), default=str),
        "units": json.dumps({c.name: si_unit(c.unit) for c in ds.columns if c.unit}),  # of the stored values
        "data_units": json.dumps({c.name: c.unit for c in ds.columns if c.unit}),  # as the data came in
        "setup": json.dumps({**post.describe(), "constants": post.constants}),
        "slots": json.dumps([{"name": s.name, "base": s.base, "level": s.level, "transform": s.transform}
                             for s in post.slots]),
        "seed": -1 if seed is None else int(seed),
        "versions": json.dumps(_versions()),
        "map": json.dumps(map_result.as_dict(post.names)),
        "map_log_density": map_result.log_density,
        "optimizer": json.dumps({"starts": list(map_result.starts), "evaluations": map_result.evaluations}),
        "sampler": json.dumps({
            "nwalkers": nw, "n_steps": run.n_steps, "burn": run.burn, "thin": run.thin,
            "moves": describe_moves(), "settings": sampler_settings(), "tau": dict(zip(post.names, run.tau.tolist())),
            "ess_emcee": dict(zip(post.names, run.ess_emcee.tolist())), "rhat_max": run.rhat_max,
            "importance": list(importance), "adaptation": list(run.adaptation),
            "acceptance_mean": float(run.acceptance.mean()), "acceptance_min": float(run.acceptance.min()),
            "converged": run.converged, "reasons": list(run.reasons), "evaluations": run.evaluations}),
        "support_counts": json.dumps(dict(post.counts), default=int),
        "support_condition": post.model.support,
    }
    found, notes = assess_run(post, run)
    attrs["warnings"], attrs["notes"] = json.dumps(found), json.dumps(notes)
    observed = {o: post.y[o] for o in post.observables}
    sample_stats = {"lp": lp_nat.reshape(nw, nd),
                    "acceptance": np.broadcast_to(run.acceptance[:, None], (nw, nd)).copy()}
    tree = from_dict({"posterior": posterior, "prior": prior_group, "sample_stats": sample_stats,
                      "observed_data": observed, "constant_data": constant,
                      **_derived_group(post, theta, nw, nd, dims, coords, attrs)},
                     dims=dims, coords=coords, attrs={"/": attrs})
    return annotate(tree, post), deferred


@dataclass(frozen=True)
class _Deferred:
    """What completes a fit's tree: its draws ``theta`` (nwalkers * ndraws, d), natural
    units, and the seed of the predictive draws' generator (drawn by :func:`_build_tree`)."""
    theta: np.ndarray
    nwalkers: int
    ndraws: int
    seed: np.ndarray

    def draws(self, every=1, walker_step=1):
        """The draws of the deferred groups: every ``every``-th draw of every ``walker_step``-th
        walker, (k, d)."""
        d = self.theta.shape[1]
        return self.theta.reshape(self.nwalkers, self.ndraws, d)[::walker_step, ::every].reshape(-1, d)

    def groups(self, post, every=1, walker_step=1):
        """The :data:`DEFERRED` groups as a DataTree, each variable (chain, draw, obs_id); with
        ``every`` or ``walker_step`` > 1 on those draws only (``chain`` / ``draw`` coordinates kept)."""
        _fitting()
        ll, simulated = post.replicate(self.draws(every, walker_step), np.random.default_rng(self.seed))
        chains, kept = np.arange(self.nwalkers)[::walker_step], np.arange(self.ndraws)[::every]
        shape = (len(chains), len(kept), post.n)
        with warnings.catch_warnings():  # one draw of a few walkers is meant (memory thinning)
            warnings.filterwarnings("ignore", "Found chain dimension to be longer than draw")
            return from_dict({"log_likelihood": {o: v.reshape(shape) for o, v in ll.items()},
                              "posterior_predictive": {o: v.reshape(shape) for o, v in simulated.items()}},
                             dims={o: ["obs_id"] for o in post.observables},
                             coords={"obs_id": np.arange(post.n), "chain": chains, "draw": kept})


#: Share of the available memory (:func:`available_memory`) the deferred groups may take while
#: they are built: 2 groups x observables x draws x rows float64, counted twice (the arrays and
#: the tree's copy; a save adds the file's image, about one copy more).  Over it,
#: :meth:`Fit.complete` keeps every k-th draw of each walker in them, and when one draw per
#: walker is still over it, one draw of every j-th walker (recorded as ``pointwise_thinned``;
#: the posterior group keeps every draw); when a single draw is over it, :func:`fit` refuses
#: before the MAP.
MEMORY_FRACTION = 0.25


def available_memory():
    """Bytes of memory available now (psutil if installed, else the free physical pages)."""
    return _available_memory()


def pointwise_bytes(n_obs, n_rows, n_draws):
    """Peak bytes of the deferred groups for ``n_draws`` draws (see :data:`MEMORY_FRACTION`)."""
    return 2 * 2 * 8 * n_obs * n_rows * n_draws


def _ordinal(k):
    return f"{k}{'th' if 10 <= k % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(k % 10, 'th')}"


def _size(nbytes):
    return f"{nbytes / 2**30:.1f} GiB" if nbytes >= 2**30 else f"{nbytes / 2**20:.1f} MiB"


def _memory_budget(post):
    """(bytes one draw of the deferred groups takes, the budget): InputError when a single draw
    is over the budget (checked by :func:`fit` before the MAP, and at completion)."""
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


def _thinning(post, deferred):
    """(every, walker_step, note): the draws of the deferred groups that fit the memory budget."""
    per_draw, budget = _memory_budget(post)
    nw, nd = deferred.nwalkers, deferred.ndraws
    total = per_draw * nw * nd
    if total <= budget:
        return 1, 1, None
    fits = int(budget // per_draw)  # draws within the budget (>= 1, see _memory_budget)
    if fits >= nw:
        every, walker_step = math.ceil(nd / (fits // nw)), 1
        which = f"every {_ordinal(every)} draw of each walker"
    else:
        every, walker_step = nd, math.ceil(nw / fits)
        which = f"one draw of every {_ordinal(walker_step)} walker"
    kept = len(range(0, nw, walker_step)) * len(range(0, nd, every))
    note = (f"pointwise log-likelihood and predictive draws on {which} ({kept} of {nw * nd}): all draws would "
            f"need {_size(total)}, over {MEMORY_FRACTION:.0%} of the available memory ({_size(budget / MEMORY_FRACTION)})")
    return every, walker_step, note


def _derived_group(post, theta, nw, nd, dims, coords, attrs):
    """The card's ``[derived]`` quantities on every draw: one value per level of its ``over``
    columns (and of the columns parameters are split by), as a ``derived`` group."""
    spec = post.model.derived
    if not spec:
        return {}
    attrs["derived"] = json.dumps({"function": spec["function"], "quantities": dict(spec["quantities"])})
    cols = list(spec["over"]) + [c for cs in post.split.values() for c in cs if c not in spec["over"]]
    labels = _level_labels(post.dataset.frame, cols, post.dataset) if cols else ["all"] * post.n
    levels = list(dict.fromkeys(labels))
    first = [labels.index(v) for v in levels]
    out = {}
    params = {p: theta[:, j:j + 1] if isinstance(j, int) else theta[:, j[first]] for p, j in post._param_index.items()}
    for name, v in post.model.derive(params, {c: x[first] for c, x in post.x.items()}, post.constants).items():
        v = np.broadcast_to(v, (len(theta), len(first)))
        out[name] = v.reshape(nw, nd, len(levels)) if cols else v.reshape(nw, nd)
        if cols:
            dims[name] = [",".join(cols)]
    if cols:
        coords[",".join(cols)] = levels
    return {"derived": out}


def _derived_summary(tree):
    """Rows of :meth:`Fit.summary` for the ``derived`` group (no MAP, tau or contraction)."""
    if "derived" not in tree.children:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from arviz_stats import summary

        table = summary(tree, group="derived", ci_kind="hdi", ci_prob=0.94, round_to="none")
    table = table.rename(columns={"hdi94_lb": "hdi_3%", "hdi94_ub": "hdi_97%"})
    table.index = [_slot_name(i) for i in table.index]
    units = json.loads(tree.attrs["derived"])["quantities"]
    table["note"] = [f"derived [{units[i.split('[')[0]]}]" for i in table.index]
    return table


def _misfit_line(fit):
    """One line on the fit's check of its fit to the data (:mod:`skinfit.analysis.misfit`)."""
    if fit.pending:
        return "fit to the data: checked when the pointwise draws are computed (Fit.complete, save, skinfit fit)"
    if "misfit" not in fit.attrs:
        return "fit to the data: not checked (saved before skinfit checked it)"
    r = fit.attr("misfit")
    if r.get("underpowered"):
        return (f"fit to the data: NOT CHECKED: {r['draws']} pointwise draws (memory) cannot give p-values below "
                f"{r['alpha']:g}/{r['m']}")
    pk = r.get("pareto_k")
    bad = [c["check"] for c in r["checks"] if c["warn"]] + (["pareto_k"] if pk and pk["warn"] else [])
    return (f"fit to the data: {'evidence of MISFIT (' + ', '.join(bad) + ')' if bad else 'no misfit found'}: "
            f"{r['m']} posterior-predictive checks on {r['draws']} draws, smallest p "
            f"{min(c['p'] for c in r['checks']):.3g} (warns below {r['alpha']:g}/{r['m']}); PSIS-LOO Pareto k > 0.7 at "
            + (f"{pk['count']} rows" if pk else "- rows (not computed)"))


def wall_time_text(t, pending=False):
    """The timings of a fit (see :func:`fit`) in one line, as ``skinfit fit`` and the report's
    diagnostics show them; the deferred groups' time once computed ('deferred' while
    :attr:`Fit.pending`; nothing for a fit saved before they were deferred, whose ``tree_s``
    includes them)."""
    if t.get("resumed"):
        text = (f"resumed from a checkpoint (MAP {t['map_s']:.2f} s in the first run), sampling "
                f"{t['sampling_s']:.2f} s over all runs, result tree {t['tree_s']:.2f} s, this call {t['total_s']:.2f} s")
    else:
        text = (f"MAP {t['map_s']:.2f} s, importance start {t['start_s'] - t['map_s']:.2f} s, "
                f"sampling {t['sampling_s']:.2f} s, result tree {t['tree_s']:.2f} s, total {t['total_s']:.2f} s")
    if "pointwise_s" in t:
        return f"{text}; pointwise log-likelihood and predictive draws {t['pointwise_s']:.2f} s (on first use)"
    return f"{text}; pointwise log-likelihood and predictive draws deferred until first use" if pending else text


@lru_cache(maxsize=1)
def _versions():
    out = {}
    for pkg in _VERSIONED:
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


class Fit:
    """The result of :func:`fit`: an ArviZ DataTree plus convenience views.

    ``fit.idata`` is the DataTree; ``fit.summary()`` a table; ``fit.save(path)`` writes NetCDF.
    A fresh fit defers the groups of :data:`DEFERRED` (:attr:`pending`): :attr:`idata`,
    :meth:`complete` and :meth:`save` compute them; :attr:`attrs`, :meth:`group` of any other
    group, :meth:`summary`, :meth:`report_text` and the provenance properties do not.
    """

    def __init__(self, idata, posterior=None, *, deferred=None, stored=None, path=None):
        self._tree = idata
        self._path = None if path is None else Path(path)
        self._posterior = posterior
        self._deferred = deferred
        self._stored = stored  # a _StoredGroups: groups of DEFERRED still in the file (load_fit)
        self._summary = None  # (key, table) of the last summary(): see _summary_key

    @property
    def path(self):
        """The file a loaded fit was read from (:func:`load_fit`); None for a fit made here."""
        return self._path

    @property
    def pending(self):
        """True until the groups of :data:`DEFERRED` are in the tree."""
        return self._deferred is not None

    @property
    def idata(self):
        """The complete ArviZ DataTree (computes the deferred groups on first access, or reads
        them from the file of a loaded fit)."""
        return self.complete()._tree

    @property
    def partial_tree(self):
        """The tree as held now: every group but, until computed or read, those of
        :data:`DEFERRED`; never computes or reads them (content hashes, summaries)."""
        return self._tree

    def complete(self) -> Fit:
        """Compute the deferred groups, if pending, and put them in the tree in ArviZ's order
        (:data:`GROUPS`), with their time as ``pointwise_s`` in ``attr("timings")``; for a
        loaded fit, read them from its file.  Returns the fit.  The root attributes are kept
        (e.g. an evidence already cached)."""
        if self._stored is not None:
            self._tree, self._stored = self._stored.read(self._tree), None
        if self._deferred is None:
            return self
        t0 = time.perf_counter()
        every, walker_step, note = _thinning(self.posterior, self._deferred)
        if note:
            warnings.warn(f"{self.model_id} on {self.dataset_id}: {note}", UserWarning, stacklevel=2)
        tree, extra = self._tree, annotate(self._deferred.groups(self.posterior, every, walker_step), self.posterior)
        nodes = {n: tree[n] for n in tree.children} | {n: extra[n] for n in extra.children}
        tree = xr.DataTree.from_dict({"/": tree.to_dataset(inherit=False)}
                                     | {n: nodes[n].to_dataset(inherit=False) for n in sorted(nodes, key=GROUPS.index)})
        if note:
            tree.attrs["pointwise_thinned"] = json.dumps({"every": every, "walker_step": walker_step, "note": note})
        t1 = time.perf_counter()
        self._check_misfit(tree, extra, self._deferred.draws(every, walker_step))
        timings = json.loads(tree.attrs["timings"])
        tree.attrs["timings"] = json.dumps(timings | {"pointwise_s": t1 - t0, "misfit_s": time.perf_counter() - t1})
        self._tree, self._deferred = tree, None
        return self

    def _check_misfit(self, tree, extra, theta):
        """The fit's checks of its own fit to the data (:mod:`skinfit.analysis.misfit`) on the deferred
        groups just computed: the record as ``attrs["misfit"]``, each failed check appended to
        ``attrs["warnings"]`` (so to :attr:`warnings`, :meth:`report_text`, the saved file and
        the report) and warned as a :class:`~skinfit.analysis.misfit.MisfitWarning`."""
        from skinfit.analysis.misfit import MisfitWarning, check_fit, misfit_messages

        post = self.posterior
        pp, ll = extra["posterior_predictive"], extra["log_likelihood"]
        y_rep = {o: pp[o].values.reshape(-1, post.n) for o in post.observables}
        log_lik = sum(ll[o].values for o in post.observables)
        ess = self.attr("sampler").get("ess_emcee", {})
        reff = float(np.clip(np.mean(list(ess.values())) / log_lik.shape[0] / log_lik.shape[1], 0.05, 1.0)) \
            if ess else 1.0
        record = check_fit(post, theta, y_rep, log_lik=log_lik, reff=reff)
        found = misfit_messages(record)
        tree.attrs["misfit"] = json.dumps(record)
        tree.attrs["warnings"] = json.dumps(json.loads(tree.attrs.get("warnings", "[]")) + found)
        for w in found:
            warnings.warn(f"{self.model_id} on {self.dataset_id}: {w['message']}", MisfitWarning, stacklevel=3)

    @property
    def attrs(self):
        """The tree's root attributes (provenance, timings, evidence): a mutable dict; never
        computes the deferred groups."""
        return self._tree.attrs

    def group(self, name):
        """One group of the tree as an ``xarray.Dataset``; only the groups of
        :data:`DEFERRED` compute them first."""
        tree = self.idata if name in DEFERRED else self._tree
        return tree[name].to_dataset()

    # ---- provenance ---------------------------------------------------------------------
    def attr(self, key):
        value = self.attrs[key]
        return json.loads(value) if isinstance(value, str) and value[:1] in "{[" else value

    @property
    def inputs(self) -> dict:
        """The model card, prior file and data file this fit read: path, sha256, where on the
        search path each was found and the files of the same id it hid
        (:func:`skinfit.io.provenance.inputs_of`)."""
        return inputs_of(self.attrs)

    @property
    def model_id(self):
        return self.attrs["model_id"]

    @property
    def dataset_id(self):
        return self.attrs["dataset_id"]

    @property
    def map(self):
        return self.attr("map")

    @property
    def warnings(self):
        """Guard-rail problems found when the fit ran (:mod:`skinfit.inference.guardrails`): a list of dicts
        ``check, status (FAIL | WARN), parameter, message``; empty for a clean fit."""
        return json.loads(self.attrs.get("warnings", "[]"))

    @property
    def notes(self):
        """Information the guard rails record that is not a failure (:mod:`skinfit.inference.guardrails`,
        e.g. a posterior that reaches a prior bound where the priors put it): dicts like
        :attr:`warnings`' with status NOTE; ``--strict`` does not act on them.  Empty for a fit
        saved before notes were recorded."""
        return json.loads(self.attrs.get("notes", "[]"))

    @property
    def converged(self):
        return bool(self.attr("sampler")["converged"])

    @property
    def posterior(self):
        """The :class:`~skinfit.posterior.Posterior` behind the fit, rebuilt from the saved tree."""
        if self._posterior is None:
            self._posterior = rebuild_posterior(self._tree)
        return self._posterior

    # ---- tables -------------------------------------------------------------------------
    def summary(self) -> pd.DataFrame:
        """Per parameter: its SI unit, mean, sd, 3%/97% HDI, R-hat, bulk/tail ESS, MAP, tau, contraction.

        ``contraction`` is 1 - var_posterior / var_prior, in the sampling coordinate (log for
        positive parameters): near 1 the data determined the parameter; below 0.5 the
        posterior is mostly its prior and ``note`` says so (e.g. ``tau0`` of electroadhesion,
        which the forces determine only through tau0*beta0 and tau0*phi).

        Computed once per content (a copy returned): a report asks for it several times a fit.
        :meth:`save` stores it in the file (root attribute ``summary``, with the sha256 of what
        it was computed from, :meth:`_summary_key`), and a loaded fit whose draws, warnings and
        records still have that hash shows the stored table (the same numbers) without
        computing it again, nor importing arviz_stats and scipy.stats; after any edit of those
        it is computed afresh.
        """
        key = self._summary_key()
        if self._summary is not None and self._summary[0] == key:
            return self._summary[1].copy()
        table = _summary_from_attr(self._tree.attrs.get(SUMMARY_ATTR), key, self._slot_names())
        if table is None:
            table = self._compute_summary()
        table.attrs["warnings"] = self.warnings  # guard rails and misfit (skinfit.inference.guardrails, skinfit.analysis.misfit)
        table.attrs["notes"] = self.notes  # information, not failures (skinfit.inference.guardrails)
        self._summary = (key, table)
        return table.copy()

    def content_hash(self):
        """sha256 of the fit's content but what is computed from it: the arrays of every group
        but those of :data:`DEFERRED` (pointwise log-likelihood and predictive draws, up to
        200 MB, functions of the posterior and the seeds in the attributes; never computed or
        read for this) with their dimensions and attributes (units), and the root attributes but
        :data:`CACHED_ATTRS` (evidence, LOO and the stored summary, which a comparison or a save
        adds to a file).  Keys the stored summary, the report's figures and the population cache."""
        import hashlib

        h = hashlib.sha256()
        tree = self._tree
        for name in sorted(set(tree.children) - set(DEFERRED)):
            ds = tree[name].to_dataset()
            for var in sorted(ds.variables):
                da = ds[var]
                values = da.values
                # text as text: a fit in memory holds str objects where its file gives '<U' arrays
                text = values.dtype.kind in "OUS"
                h.update(f"{name}/{var}{da.dims}{values.shape}{'text' if text else values.dtype.str}".encode())
                h.update(json.dumps(da.attrs, sort_keys=True, default=_plain_json).encode())
                h.update(repr([str(v) for v in values.ravel().tolist()]).encode() if text
                         else np.ascontiguousarray(values).tobytes())
        attrs = {k: v for k, v in tree.attrs.items() if k not in CACHED_ATTRS}
        h.update(json.dumps(attrs, sort_keys=True, default=_plain_json).encode())
        return h.hexdigest()

    @property
    def summary_stored(self):
        """True when the root attributes hold this fit's summary table for its current content
        (:meth:`summary` then reads it instead of computing it)."""
        return _summary_from_attr(self._tree.attrs.get(SUMMARY_ATTR), self._summary_key(),
                                  self._slot_names()) is not None

    def _slot_names(self):
        return [s["name"] for s in self.attr("slots")]

    def _summary_key(self):
        """sha256 of all :meth:`summary` is computed from: the fit's content
        (:meth:`content_hash`: draws with their dimensions, levels and units, warnings, MAP,
        sampler record, slots, priors, derived quantities), with the table's format version
        :data:`SUMMARY_FORMAT`."""
        import hashlib

        return hashlib.sha256(f"skinfit summary {SUMMARY_FORMAT}\0{self.content_hash()}".encode()).hexdigest()

    def _compute_summary(self):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            from arviz_stats import summary

            table = summary(self._tree, ci_kind="hdi", ci_prob=0.94, round_to="none",
                               var_names=[v for v in self._tree["posterior"].data_vars])
        table = table.rename(columns={"hdi94_lb": "hdi_3%", "hdi94_ub": "hdi_97%"})
        table.index = [_slot_name(i) for i in table.index]
        sampler = self.attr("sampler")
        post_ds = self.group("posterior")
        priors = _priors_from_attrs(self.attrs)
        rows = {s["name"]: s for s in self.attr("slots")}
        contraction, notes = [], []
        for name in table.index:
            slot = rows[name]
            c = np.nan
            if slot["base"] in priors:
                prior = priors[slot["base"]]
                q = prior.ppf((np.arange(4000) + 0.5) / 4000)
                values = _slot_values(post_ds, slot)
                if prior.lower >= 0:  # the sampling coordinate: log for positive parameters
                    q, values = np.log(q), np.log(values)
                c = 1.0 - float(np.var(values)) / float(np.var(q))
            contraction.append(c)
            notes.append("; ".join(["mostly prior: the data barely determine it"] * (c < 0.5)
                                   + [f"ON A BOUND: {w['message']}" for w in self.warnings
                                      if w["check"] == "bound" and w["parameter"] == name]
                                   + [f"at a bound (note): {w['message']}" for w in self.notes
                                      if w["parameter"] == name]))
        table["map"] = [self.map[n] for n in table.index]
        table["tau"] = [sampler["tau"][n] for n in table.index]
        table["contraction"] = contraction
        table["note"] = notes
        table = pd.concat([table, _derived_summary(self._tree)])
        table["unit"] = [self._unit(n) for n in table.index]
        return table[list(SUMMARY_COLUMNS)]

    def _unit(self, name):
        """SI unit of a summary row (``E_star``, ``alpha[75]``, a derived quantity), from the
        ``units`` attr of its variable in the tree ('' for fits saved without them)."""
        base = name.split("[")[0]
        for group in ("posterior", "derived"):
            if group in self._tree.children and base in self._tree[group].data_vars:
                return self._tree[group][base].attrs.get("units", "")
        return ""

    def diagnostics(self):
        """Sampler, optimiser and support diagnostics as one dict."""
        return {"sampler": self.attr("sampler"), "optimizer": self.attr("optimizer"),
                "timings": self.attr("timings"), "support_counts": self.attr("support_counts"),
                "support_condition": self.attrs.get("support_condition", "")}

    def report_text(self, summary: pd.DataFrame | None = None) -> str:
        """The text printed by ``skinfit fit``: summary table and diagnostics (``summary``:
        the table of :meth:`summary` if the caller has it already)."""
        s = self.attr("sampler")
        t = self.attr("timings")
        c = self.attr("support_counts")
        seed = int(self.attrs.get("seed", -1))
        seed_text = ("a numpy Generator (not recorded)" if seed < 0 else
                     f"{seed}{' (drawn; --seed ' + str(seed) + ' repeats this fit)' if self.attrs.get('seed_drawn') else ''}")
        lines = [f"model {self.model_id}  data {self.dataset_id}  ({self.attrs['dataset_sha256'][:12]})",
                 *input_lines(self.attrs),
                 f"seed: {seed_text}",
                 f"converged: {'yes' if s['converged'] else 'NO: ' + '; '.join(s['reasons'])}",
                 *[f"{w['status']}: {w['message']}" for w in self.warnings if w["check"] != "convergence"],
                 *[f"NOTE: {n['message']}" for n in self.notes],
                 _misfit_line(self),
                 *(["note: " + self.attr("pointwise_thinned")["note"]] if "pointwise_thinned" in self.attrs else []),
                 f"walkers {s['nwalkers']}  steps {s['n_steps']}  burn-in {s['burn']}  thin {s['thin']}  "
                 f"acceptance mean {s['acceptance_mean']:.3f} (min {s['acceptance_min']:.3f})  "
                 f"max R-hat {s['rhat_max']:.4f}",
                 f"moves: {s['moves']}",
                 "proposal: importance start, effective sample size "
                 + (", ".join(f"{r['ess']:.0f}" for r in s.get("importance", [])) or "-")
                 + f" of {s['importance'][0]['draws'] if s.get('importance') else 0} draws per round; refitted "
                 f"during sampling at steps {', '.join(str(a['step']) for a in s.get('adaptation', []) if a['refit']) or 'none'}",
                 f"wall time: {wall_time_text(t, self.pending)}",
                 f"log-density evaluations {c['evaluations']}: outside prior bounds {c['outside_prior']}, "
                 f"outside the physical support {c['outside_support']}"
                 + (f" ({self.attrs.get('support_condition')})" if c["outside_support"] else ""),
                 ""]
        with pd.option_context("display.width", 200, "display.max_columns", 20,
                               "display.float_format", "{:.4g}".format):
            lines.append((self.summary() if summary is None else summary).to_string())
        return "\n".join(lines)

    def save(self, path: str | os.PathLike) -> Path:
        """Write the fit as NetCDF, atomically (temporary file + rename), with every group (a
        pending fit is completed first) and the sha256 of each group and of the root attributes
        (:mod:`skinfit.io.integrity`), which :func:`load_fit` checks.  ``path`` is the file (a
        directory, a device such as /dev/null or a FIFO there is refused first)."""
        path = check_output_file(path, "Fit.save", "path", "fit")
        path.parent.mkdir(parents=True, exist_ok=True)
        # HDF5 writes into memory, never onto a disk that may fill (on a full disk it crashed the
        # process at exit, rc 139); the bytes go out by plain writes, so a full or read-only disk
        # is an OSError with the previous file in place
        tree = self.idata
        schema = tree.attrs.get(integrity.SCHEMA_ATTR)
        if not isinstance(schema, (int, np.integer)) or schema < integrity.CHECKED_SCHEMA:  # an older file saved again
            tree.attrs[integrity.SCHEMA_ATTR] = integrity.CHECKED_SCHEMA  # (before its summary's key is computed)
        try:
            tree.attrs[SUMMARY_ATTR] = _summary_to_attr(self.summary(), self._summary_key())
        except Exception as exc:  # noqa: BLE001 - the summary is only kept to save time: the fit is saved without it
            tree.attrs.pop(SUMMARY_ATTR, None)
            warnings.warn(f"{self.model_id} on {self.dataset_id}: saved without its summary table "
                          f"({type(exc).__name__}: {exc}); it is computed when read", UserWarning, stacklevel=2)
        dask = sys.modules.get("dask")  # in a Dask worker xarray would take a distributed lock named by the target
        integrity.stamp(tree)  # the tree in memory as it is read back: with its checksums
        with (dask.config.set(scheduler="synchronous") if dask is not None else nullcontext()), \
                _dask_unimported():
            data = integrity.seal(tree.to_netcdf(engine="h5netcdf"))  # and the sha256 of its bytes
        free = shutil.disk_usage(path.parent).free
        if free < len(data) + (1 << 20):
            raise OSError(errno.ENOSPC, f"no space to save the fit: {len(data) / 2**20:.1f} MiB needed, "
                                        f"{free / 2**20:.1f} MiB free", str(path))
        from skinfit.inference.checkpoint import replace_atomic

        replace_atomic(path, data)  # a unique temp file per writer; a killed writer's is removed by the next run
        return path

    def _repr_html_(self) -> str:
        """Notebook view: model and data, the seed, the convergence verdict with its reasons,
        the guard-rail warnings and notes and the summary table."""
        from html import escape

        s = self.attr("sampler")
        verdict = ("<b style='color:#1a7f37'>converged</b>" if s["converged"] else
                   "<b style='color:#cf222e'>NOT converged</b>: " + escape("; ".join(s["reasons"])))
        items = "".join(f"<li><b>{escape(w['status'])}</b> {escape(w['message'])}</li>"
                        for w in self.warnings + self.notes)
        seed = int(self.attrs.get("seed", -1))
        with pd.option_context("display.float_format", "{:.4g}".format):
            table = self.summary().to_html(float_format="{:.4g}".format, border=0)
        return (f"<div><p><b>{escape(self.model_id)}</b> on <b>{escape(self.dataset_id)}</b> "
                f"(data {escape(self.attrs['dataset_sha256'][:12])}; seed {seed if seed >= 0 else 'not recorded'})"
                f"<br>{verdict}; walkers {s['nwalkers']}, steps {s['n_steps']}, max R-hat {s['rhat_max']:.4f}</p>"
                + (f"<ul>{items}</ul>" if items else "") + table + "</div>")

    def __repr__(self):
        return f"Fit({self.model_id!r} on {self.dataset_id!r}, converged={self.converged})"


@contextmanager
def _dask_unimported():
    """While a process that has not imported Dask (or not its ``distributed``) writes a fit:
    that package unimportable (as without the ``dask`` extra).  xarray's netCDF writer imports
    them (0.1-0.8 s) only to ask which Dask scheduler is active, and none can be in a process
    that has not imported them: the answer "none" gives the same lock, and the file written is
    the same.  Another thread that imports the package meanwhile gets an ImportError."""
    name = next((n for n in ("dask", "distributed") if n not in sys.modules), None)
    if name is None:  # both imported (a Dask worker, a Client), or made unimportable by someone else
        yield
        return
    sys.modules[name] = None
    try:
        yield
    finally:
        if name in sys.modules and sys.modules[name] is None:
            del sys.modules[name]


def as_fit(obj, where="fit", field=None) -> Fit:
    """A :class:`Fit` from a Fit, its DataTree or the path of a saved fit (:func:`load_fit`);
    InputTypeError naming ``where`` (the function) and ``field`` (the argument) for anything else."""
    if isinstance(obj, Fit):
        return obj
    if isinstance(obj, (str, os.PathLike)):
        return load_fit(obj)
    if isinstance(obj, xr.DataTree) and "model_id" in obj.attrs:
        return Fit(obj)
    raise InputTypeError(where, f"expected a skinfit Fit, its DataTree or the path of a fit.nc (got {shown(obj)})",
                         field=field)


def as_fits(fits, where, field="fits"):
    """A list of Fits from a sequence (or the values of a mapping) of what :func:`as_fit`
    accepts; InputTypeError naming the position of the first that is none of them."""
    if isinstance(fits, Mapping):
        fits = list(fits.values())
    if isinstance(fits, (str, bytes, os.PathLike, Fit)) or not isinstance(fits, Iterable):
        raise InputTypeError(where, f"expected a list of fits (Fit objects or paths of fit.nc) (got {shown(fits)})",
                             field=field)
    return [as_fit(f, where, f"{field}[{i}]") for i, f in enumerate(fits)]


def fit_file(path) -> Path:
    """The file of a saved fit: ``path`` itself, or ``path/fit.nc`` for a run directory (a
    regular file: a FIFO or a device is refused before HDF5 opens it and waits on it)."""
    path = Path(check_path(path, "load_fit", None, "the path of a fit.nc or of its run directory"))
    if path.is_dir():
        path = path / "fit.nc"
    if not path.exists():
        raise InputError(path, "no such fit file")
    return check_input_file(path, "fit file")


def load_fit(path: str | os.PathLike) -> Fit:
    """Load a fit saved by :meth:`Fit.save`.

    The groups of :data:`DEFERRED` (pointwise log-likelihood and predictive draws, most of a
    file) are read when first used (:attr:`Fit.idata`, :meth:`Fit.group`, :meth:`Fit.complete`),
    from the same file: if it has been replaced or changed meanwhile, that read raises
    InputError rather than mix two results.  Groups are read with h5py directly
    (:mod:`skinfit.results._netcdf`) and decoded by xarray's CF decoding: the same tree as
    ``xarray.open_datatree``, in under half of its time. A file of another layout is read by
    h5netcdf (groups of variables) or ``xarray.open_datatree`` whole (nested groups, variables
    at the root)."""
    path = fit_file(path)
    try:
        stored = _StoredGroups(path)
        tree = stored.read_light()
    except InputError:
        raise
    except _UNREADABLE as exc:
        raise InputError(path, f"not a readable skinfit result ({_one_line(exc)})") from None
    if "model_id" not in tree.attrs:
        raise InputError(path, "not a skinfit result (no model_id attribute)")
    return Fit(tree, stored=stored if stored.names else None, path=path)


#: What reading a damaged or foreign file can raise (HDF5's errors through h5py, numpy's for a
#: corrupted shape, decoding errors): each becomes one line naming the file.
_UNREADABLE = (OSError, ValueError, KeyError, TypeError, IndexError, RuntimeError, AttributeError, OverflowError,
               MemoryError)


def _one_line(exc):
    return f"{type(exc).__name__}: {' '.join(str(exc).split())}"[:300]


class _StoredGroups:
    """The groups of :data:`DEFERRED` of a saved fit, left in its file until first used; the
    file is identified by device, inode, size and modification time when first read."""

    def __init__(self, path):
        self.path = Path(path)
        self.identity = self._identity()
        self.names = []
        self.order = []
        self.sealed = False  # its bytes checked against the sha256 they end with (skinfit.io.integrity)
        self.record = None  # else its content's checksums, checked as each group is read

    def _identity(self):
        st = os.stat(self.path)
        return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns

    def read_light(self):
        """The tree without the groups of :data:`DEFERRED` (listed in ``names``)."""
        from skinfit.results._netcdf import NotPlain, read_groups

        self.sealed = integrity.check_file(self.path)  # its bytes, before HDF5 parses any of them
        try:  # the layout Fit.save writes, read directly; any other by h5netcdf
            order, attrs, nodes = read_groups(self.path, lambda g: g not in DEFERRED)
        except NotPlain:
            import h5netcdf

            with h5netcdf.File(self.path, "r", decode_vlen_strings=True) as h:
                order = list(h.groups)  # names only: a group's metadata is read when it is opened
                light = {g: h.groups[g] for g in order if g not in DEFERRED}
                if h.variables or any(g.groups for g in light.values()):
                    return self._whole()  # not Fit.save's layout
                attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in h.attrs.items()}
                nodes = {g: _decoded(group) for g, group in light.items()}
        self.record = integrity.take(self.path, attrs, order, sealed=self.sealed)  # else its content's checksums
        integrity.verify(self.path, self.record, groups=nodes)
        self.order, self.names = order, [g for g in order if g in DEFERRED]
        return xr.DataTree.from_dict({"/": xr.Dataset(attrs=attrs)} | nodes)

    def _whole(self):
        """The whole tree of a file of another layout (``xarray.open_datatree``), checked."""
        tree = xr.open_datatree(self.path, engine="h5netcdf").load()
        record = integrity.take(self.path, tree.attrs, list(tree.children), sealed=self.sealed)
        integrity.verify(self.path, record, groups=integrity.groups_of(tree))
        return tree

    def read(self, tree):
        """``tree`` with the groups of ``names`` read from the file, in the file's order."""
        try:
            same = self._identity() == self.identity
        except OSError:
            same = False
        if not same:
            raise InputError(self.path, "changed or removed since the fit was loaded: load it again "
                                        "(its pointwise log-likelihood and predictive draws are read on first use)")
        from skinfit.results._netcdf import NotPlain, read_groups

        try:
            try:
                extra = read_groups(self.path, lambda g: g in self.names)[2]
            except NotPlain:
                extra = self._read_h5netcdf()
        except InputError:
            raise
        except _UNREADABLE as exc:
            raise InputError(self.path, f"its pointwise groups cannot be read ({_one_line(exc)})") from None
        integrity.verify(self.path, self.record, groups=extra)
        nodes = {n: tree[n].to_dataset(inherit=False) for n in tree.children} | extra
        order = [g for g in self.order if g in nodes] + [g for g in nodes if g not in self.order]
        return xr.DataTree.from_dict({"/": tree.to_dataset(inherit=False)} | {n: nodes[n] for n in order})

    def _read_h5netcdf(self):
        """The groups of ``names`` read by h5netcdf (a file of another layout than Fit.save's)."""
        import h5netcdf

        with h5netcdf.File(self.path, "r", decode_vlen_strings=True) as h:
            groups = {g: h.groups[g] for g in self.names}
            if any(group.groups for group in groups.values()):
                raise InputError(self.path, f"groups inside {', '.join(g for g in groups if groups[g].groups)}: "
                                            "not a fit file skinfit writes")
            return {g: _decoded(group) for g, group in groups.items()}


def _decoded(group):
    """One h5netcdf group as an xarray Dataset, decoded as ``xarray.open_dataset`` decodes it."""
    variables = {k: xr.Variable(v.dimensions, v[...], attrs=dict(v.attrs)) for k, v in group.variables.items()}
    attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in group.attrs.items()}
    return xr.decode_cf(xr.Dataset(variables, attrs=attrs))


#: Root attribute holding a fit's summary table (:meth:`Fit.summary`), and the table's format:
#: raise it when the table's columns or their computation change, so older stored tables are
#: computed again.
SUMMARY_ATTR = "summary"
SUMMARY_FORMAT = 1
SUMMARY_COLUMNS = ("unit", "mean", "sd", "hdi_3%", "hdi_97%", "r_hat", "ess_bulk", "ess_tail", "map", "tau",
                   "contraction", "note")
#: Root attributes a saved fit may gain without its draws or records changing (evidence and LOO
#: by a comparison, the stored summary, the file's checksums): left out of content hashes such as the report's
#: figure cache (:meth:`Fit.content_hash`).
CACHED_ATTRS = ("evidence", "loo", SUMMARY_ATTR, integrity.RECORD)


def _plain_json(value):
    """JSON default: numpy scalars and arrays as the Python values a fit in memory holds
    (a loaded fit's integer attributes are numpy integers)."""
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    return str(value)


def _summary_to_attr(table, key):
    """The summary table as JSON text, with the sha256 ``key`` of its inputs; floats as
    Python writes them (repr: exact round trip), NaN as NaN."""
    columns = [{"name": c, "dtype": str(table[c].dtype), "values": table[c].tolist()} for c in table.columns]
    return json.dumps({"key": key, "index": [str(i) for i in table.index], "columns": columns})


def _summary_from_attr(text, key, slots):
    """The table stored by :func:`_summary_to_attr` when its key is ``key`` and it has the
    columns of :data:`SUMMARY_COLUMNS` and a row for each of ``slots`` (the sampled parameters'
    names), a value per row in each column; None when absent, of other inputs, or damaged
    (then it is computed again, and the next save rewrites it)."""
    if not isinstance(text, str) or not text:
        return None
    try:
        doc = json.loads(text)
        index, columns = doc["index"], doc["columns"]
        if (doc.get("key") != key or [c["name"] for c in columns] != list(SUMMARY_COLUMNS)
                or not set(slots) <= set(index) or len(set(index)) != len(index)
                or any(len(c["values"]) != len(index) for c in columns)):
            return None
        return pd.DataFrame({c["name"]: pd.Series(c["values"], dtype=c["dtype"], index=index) for c in columns},
                            index=index)
    except (ValueError, TypeError, KeyError, AttributeError):
        return None


def _slot_name(label):
    return label.replace("'", "")


def _slot_values(post_ds, slot):
    da = post_ds[slot["base"]]
    if slot["level"] is not None:
        dim = [d for d in da.dims if d not in ("chain", "draw")][0]
        da = da.sel({dim: slot["level"]})
    return da.values.ravel()


def _priors_from_attrs(attrs, check_mass=True):
    """The prior of each parameter, from the prior file's text saved in a fit's root ``attrs``
    (``check_mass``: see :func:`skinfit.io.priors.parse_prior`)."""
    import tomllib

    from skinfit.io.priors import parse_prior

    doc = tomllib.loads(attrs["priors_text"])
    return {k: parse_prior(k, v, "saved priors", check_mass) for k, v in doc.items()
            if k not in ("schema_version", "model", "id")}


def rebuild_posterior(tree):
    """Reconstruct the Posterior of a saved fit from its own records (cards as saved). Imports
    the posterior and priors, not the optimiser, sampler and ArviZ's tree builder
    (:func:`_fitting`): a report's predictive check rebuilds it without fitting."""
    from types import MappingProxyType

    from skinfit.io.data import Column
    from skinfit.io.models import _parse_model_text
    from skinfit.posterior import Posterior
    from skinfit.io.priors import PriorSet

    attrs = tree.attrs
    model = _parse_model_text(attrs["model_card"], f"model card saved in fit ({attrs['model_id']})",
                              attrs["model_sha256"])
    priors = PriorSet(id=attrs["priors_id"], model=attrs["model_id"],
                      priors=MappingProxyType(_priors_from_attrs(attrs)), path="saved priors",
                      sha256=attrs["priors_sha256"], text=attrs["priors_text"])
    setup = json.loads(attrs["setup"])
    units = json.loads(attrs.get("data_units", attrs["units"]))  # the split levels' labels use them
    cd = tree["constant_data"].to_dataset()
    od = tree["observed_data"].to_dataset()
    frame = pd.DataFrame({c: cd[c].values for c in cd.data_vars} | {o: od[o].values for o in od.data_vars})
    columns = tuple(Column(c, c, units.get(c), "quantity" if c in units else "category") for c in frame.columns)
    ds = Dataset(id=attrs["dataset_id"], title="", frame=frame, columns=columns, groups=(),
                 provenance=MappingProxyType(json.loads(attrs["dataset_provenance"])), model=None,
                 path=attrs["dataset_path"], sha256=attrs["dataset_sha256"])
    return Posterior(model, priors, ds, split=setup["split"], noise=setup["noise"],
                     constants={k: v for k, v in setup["constants"].items() if k in model.constants})
