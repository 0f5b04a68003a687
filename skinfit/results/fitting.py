"""``skinfit.fit``: MAP (nlopt) -> emcee from the importance start -> diagnostics -> a :class:`Fit`.

The inference is :func:`skinfit.inference.run.run`; this builds its result: the tree
(:func:`skinfit.results.tree.build_tree`), the convergence and guard-rail warnings, the
timings, and (unless asked not to) the pointwise groups with the check of the fit to the data.
"""

from __future__ import annotations

import json
import os
import time
import warnings
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from skinfit.errors import ConvergenceWarning
from skinfit.inference.run import run
from skinfit.io.arguments import check_flag
from skinfit.io.data import Dataset
from skinfit.io.models import Model
from skinfit.io.priors import PriorSet
from skinfit.results.fit import Fit
from skinfit.results.tree import build_tree

__all__ = ["fit"]


def fit(model: str | Model, dataset: str | os.PathLike | Dataset | pd.DataFrame,
        priors: str | os.PathLike | PriorSet | Mapping | None = None, *, units: Mapping[str, str] | None = None,
        columns: Mapping[str, str] | None = None, rng: int | np.random.Generator | None = None,
        split: Mapping[str, Sequence[str]] | None = None,
        noise: str | Mapping[str, str] | None = None, constants: Mapping[str, float] | None = None,
        nwalkers: int | None = None, ess_target: float = 400, max_steps: int = 20000, progress: bool = False,
        strict: bool = False, n_global: int = 2000, n_local: int = 4, n_prior_draws: int = 2000,
        checkpoint: str | os.PathLike | None = None, resume: bool = False,
        checkpoint_every: float = 30.0, complete: bool = True) -> Fit:
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
    columns : mapping header -> skinfit name, optional
        For a DataFrame with a lab's headers: ``{"Normal force (mN)": "normal_force"}`` (a
        header's ``(unit)`` or ``[unit]`` is read as its unit).  A file is mapped once, into a
        dataset card: ``skinfit dataset init`` (docs: "Your lab's files").
    priors : PriorSet, str or mapping, optional
        Default: ``priors/<model id>.toml``.  A mapping parameter -> frozen scipy.stats
        distribution (its support the bounds; :func:`skinfit.truncate` for narrower ones) or
        prior-file table, with ``sigma`` (and ``nu`` for Student-t noise) for the noise.
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
    complete : bool
        Compute the pointwise ``log_likelihood`` and ``posterior_predictive`` groups (a value per
        posterior draw and data row each, most of a fit's memory) and check the fit to the data
        on them (:mod:`skinfit.inference.misfit`) before returning (default).  False returns at
        the converged posterior: a fit whose :attr:`Fit.pending` is true, for callers that need
        only the posterior (simulation-based calibration); :meth:`Fit.complete` (or
        :meth:`Fit.save`) completes it, with the same numbers.

    Returns
    -------
    Fit
        Its ``attr("timings")`` [s]: ``map_s`` the MAP search; ``start_s`` from the first random
        draw to the first step (the MAP search and the importance start); ``sampling_s``;
        ``tree_s`` the result tree without the pointwise groups; ``total_s`` the call up to
        there; ``resumed``; and, once the fit is complete, ``pointwise_s`` and ``misfit_s`` the
        pointwise groups and the check of the fit to the data.  A resumed fit (``resumed``
        true) had its MAP and start in the run that wrote the checkpoint: its ``map_s`` is that
        run's, ``start_s`` is 0 and ``sampling_s`` sums every run's sampling.
    """
    t_start = time.perf_counter()
    strict, complete = check_flag(strict, "fit", "strict"), check_flag(complete, "fit", "complete")
    result = run(model, dataset, priors, units=units, columns=columns, rng=rng, split=split, noise=noise,
                 constants=constants,
                 nwalkers=nwalkers, ess_target=ess_target, max_steps=max_steps, progress=progress,
                 n_global=n_global, n_local=n_local, n_prior_draws=n_prior_draws, checkpoint=checkpoint,
                 resume=resume, checkpoint_every=checkpoint_every)
    post, sampler = result.posterior, result.sampler
    if not sampler.converged:
        msg = (f"{post.model.id} on {post.dataset.id}: not converged after {sampler.n_steps} steps: "
               + "; ".join(sampler.reasons))
        if strict:
            raise RuntimeError(msg)
        warnings.warn(msg, ConvergenceWarning, stacklevel=2)
    t_tree = time.perf_counter()
    tree, pointwise = build_tree(result, n_prior_draws)
    tree.attrs["seed_drawn"] = int(result.seed_drawn)
    tree.attrs["inputs"] = json.dumps(result.inputs)
    now = time.perf_counter()
    t = result.timings
    tree.attrs["timings"] = json.dumps({"map_s": t["map_s"], "start_s": t["start_s"], "sampling_s": t["sampling_s"],
                                        "tree_s": now - t_tree, "total_s": now - t_start, "resumed": t["resumed"]})
    for w in result.warnings:  # non-convergence was warned above, a raw recording by run()
        if w["check"] not in ("convergence", "raw_series"):
            warnings.warn(f"{post.model.id} on {post.dataset.id}: {w['message']}", ConvergenceWarning, stacklevel=2)
    if not complete:
        return Fit(tree, posterior=post, pointwise=pointwise)
    tree, messages = pointwise.complete(tree, post)
    for message, category in messages:  # memory thinning, misfit
        warnings.warn(message, category, stacklevel=2)
    return Fit(tree, posterior=post)
