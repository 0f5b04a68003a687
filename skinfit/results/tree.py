"""The result tree of a fit, an ArviZ DataTree, built from an inference run.

:func:`build_tree` gives every group of :data:`~skinfit.results.fit.GROUPS` but the pointwise
``log_likelihood`` and ``posterior_predictive`` (a value per posterior draw and data row each,
most of a tree's cost), and the :class:`Pointwise` record that adds them
(:meth:`Pointwise.complete`, with the fit's check of its fit to the data,
:mod:`skinfit.inference.misfit`). The root attributes record where every number came from:
model card, prior file and dataset (with hashes and full texts), skinfit and dependency
versions, seed, MAP, optimiser status, sampler record and guard rails.
"""

import json
import time
from dataclasses import dataclass
from functools import lru_cache
from importlib import metadata

import numpy as np
import xarray as xr
from arviz_base import from_dict

from skinfit.inference.misfit import MisfitWarning, check_fit, misfit_messages
from skinfit.inference.run import pointwise_thinning
from skinfit.inference.sampling import describe_moves, sampler_settings
from skinfit.io import integrity
from skinfit.io.labels import annotate, level_labels, noise_suffix
from skinfit.io.units import si_unit
from skinfit.results.fit import GROUPS
from skinfit.results.pointwise import RECIPE, make_recipe, pointwise_tree

__all__ = ["build_tree", "Pointwise", "versions", "known_se_record"]

_VERSIONED = ("skinfit", "numpy", "scipy", "emcee", "nlopt", "arviz", "arviz-base", "arviz-stats",
              "xarray", "pandas")


def build_tree(result, n_prior_draws):
    """The tree of :class:`~skinfit.inference.run.Run` ``result`` without the pointwise groups,
    and the :class:`Pointwise` record that computes them.

    Draws from ``result.rng``, after the sampling: ``n_prior_draws`` prior draws (the ``prior``
    group), then the seed of the pointwise groups' own generator, so that they are the same
    whenever they are computed.
    """
    post, run, map_result, rng = result.posterior, result.sampler, result.map, result.rng
    nw, nd, d = run.chain.shape
    theta = post.to_theta(run.chain.reshape(-1, d))
    t_prior = post.sample_prior(n_prior_draws, rng)
    # after the prior draws, the last draw of a fit: the predictive draws' own generator
    pointwise = Pointwise(theta, nw, nd, rng.integers(2**63, size=4))
    # the chain's own log density, less the sampling map's Jacobian: log prior + log likelihood in
    # natural parameters with no further forward call
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
            constant[c] = col.to_numpy(
                dtype=object if col.dtype == object or str(col.dtype).startswith("str") else float)
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
        "seed": -1 if result.seed is None else int(result.seed),
        "versions": json.dumps(versions()),
        "map": json.dumps(map_result.as_dict(post.names)),
        "map_log_density": map_result.log_density,
        "optimizer": json.dumps({"starts": list(map_result.starts), "evaluations": map_result.evaluations}),
        "sampler": json.dumps({
            "nwalkers": nw, "n_steps": run.n_steps, "burn": run.burn, "thin": run.thin,
            "moves": describe_moves(), "settings": sampler_settings(), "tau": dict(zip(post.names, run.tau.tolist())),
            "ess_emcee": dict(zip(post.names, run.ess_emcee.tolist())), "rhat_max": run.rhat_max,
            "importance": list(result.importance), "adaptation": list(run.adaptation),
            "acceptance_mean": float(run.acceptance.mean()), "acceptance_min": float(run.acceptance.min()),
            "converged": run.converged, "reasons": list(run.reasons), "evaluations": run.evaluations}),
        "support_counts": json.dumps(dict(post.counts), default=int),
        "support_condition": post.model.support,
        "warnings": json.dumps(result.warnings), "notes": json.dumps(result.notes),
    }
    known = known_se_record(post)
    if known:  # per-row standard errors in the likelihood (observables) or reported (covariates)
        attrs["known_se"] = json.dumps(known)
        attrs["notes"] = json.dumps(result.notes + known["notes"])
    observed = {o: post.y[o] for o in post.observables}
    sample_stats = {"lp": lp_nat.reshape(nw, nd),
                    "acceptance": np.broadcast_to(run.acceptance[:, None], (nw, nd)).copy()}
    tree = from_dict({"posterior": posterior, "prior": prior_group, "sample_stats": sample_stats,
                      "observed_data": observed, "constant_data": constant,
                      **_derived_group(post, theta, nw, nd, dims, coords, attrs)},
                     dims=dims, coords=coords, attrs={"/": attrs})
    return annotate(tree, post), pointwise


@dataclass(frozen=True)
class Pointwise:
    """What completes a fit's tree: its draws ``theta`` (nwalkers * ndraws, d), natural
    units, and the seed of the predictive draws' generator (drawn by :func:`build_tree`)."""

    theta: np.ndarray
    nwalkers: int
    ndraws: int
    seed: np.ndarray

    def draws(self, every=1, walker_step=1):
        """The draws of the pointwise groups: every ``every``-th draw of every ``walker_step``-th
        walker, (k, d)."""
        d = self.theta.shape[1]
        return self.theta.reshape(self.nwalkers, self.ndraws, d)[::walker_step, ::every].reshape(-1, d)

    def groups(self, post, every=1, walker_step=1):
        """The ``log_likelihood`` and ``posterior_predictive`` groups as a DataTree, each
        variable (chain, draw, obs_id); with ``every`` or ``walker_step`` > 1 on those draws
        only (``chain`` / ``draw`` coordinates kept): :func:`~skinfit.results.pointwise.pointwise_tree`."""
        return pointwise_tree(post, self.theta, self.nwalkers, self.ndraws, self.seed, every, walker_step)

    def complete(self, tree, post):
        """``tree`` (of :func:`build_tree`, for Posterior ``post``) with the pointwise groups in
        ArviZ's order (:data:`~skinfit.results.fit.GROUPS`), and the warnings to give as
        ``(message, category)`` pairs: a note when memory thinned the draws
        (``pointwise_thinned``), then each failed check of the fit's fit to the data.

        The check's record goes in ``attrs["misfit"]``, each failed check is appended to
        ``attrs["warnings"]``, and the time of each step to ``attrs["timings"]`` (``pointwise_s``,
        ``misfit_s``); the root attributes are kept (e.g. an evidence already cached).
        """
        t0 = time.perf_counter()
        every, walker_step, note = pointwise_thinning(post, self.nwalkers, self.ndraws)
        where = f"{tree.attrs['model_id']} on {tree.attrs['dataset_id']}"
        messages = [(f"{where}: {note}", UserWarning)] if note else []
        extra = self.groups(post, every, walker_step)
        nodes = {n: tree[n] for n in tree.children} | {n: extra[n] for n in extra.children}
        tree = xr.DataTree.from_dict({"/": tree.to_dataset(inherit=False)}
                                     | {n: nodes[n].to_dataset(inherit=False) for n in sorted(nodes, key=GROUPS.index)})
        tree.attrs[RECIPE] = make_recipe(self.seed, every, walker_step, extra)  # what Fit.save writes instead
        if note:
            tree.attrs["pointwise_thinned"] = json.dumps({"every": every, "walker_step": walker_step, "note": note})
        t1 = time.perf_counter()
        found = _check_misfit(tree, extra, post, self.draws(every, walker_step))
        messages += [(f"{where}: {w['message']}", MisfitWarning) for w in found]
        timings = json.loads(tree.attrs["timings"])
        tree.attrs["timings"] = json.dumps(timings | {"pointwise_s": t1 - t0, "misfit_s": time.perf_counter() - t1})
        return tree, messages


def _check_misfit(tree, extra, post, theta):
    """The fit's checks of its own fit to the data (:func:`~skinfit.inference.misfit.check_fit`)
    on the pointwise groups ``extra`` just computed from draws ``theta``: the record as
    ``tree.attrs["misfit"]``, each failed check appended to ``tree.attrs["warnings"]``; returns
    the failed checks."""
    pp, ll = extra["posterior_predictive"], extra["log_likelihood"]
    y_rep = {o: pp[o].values.reshape(-1, post.n) for o in post.observables}
    log_lik = sum(ll[o].values for o in post.observables)
    ess = json.loads(tree.attrs["sampler"]).get("ess_emcee", {})
    reff = float(np.clip(np.mean(list(ess.values())) / log_lik.shape[0] / log_lik.shape[1], 0.05, 1.0)) \
        if ess else 1.0
    record = check_fit(post, theta, y_rep, log_lik=log_lik, reff=reff)
    found = misfit_messages(record)
    tree.attrs["misfit"] = json.dumps(record)
    tree.attrs["warnings"] = json.dumps(json.loads(tree.attrs.get("warnings", "[]")) + found)
    return found


def known_se_record(post):
    """What Posterior ``post`` does with the dataset's standard-error columns
    (:mod:`skinfit.io.known_se`), for a fit's ``known_se`` root attribute: ``observables``
    (observable -> column, median and max se in SI, the noise parameter it adds to),
    ``covariates`` (covariate -> column, largest relative se and its row) and the ``notes`` the
    fit shows (guard-rail notes: check ``known_se``, status NOTE); {} when the data have none."""
    if not post.se and not post.covariate_se:
        return {}
    obs, notes = {}, []
    for o, se in post.se.items():
        sigma = f"sigma{noise_suffix(post.observables, o)}"
        log = "; as se_i / y_i on the log scale, the delta method" if post.noise[o] == "lognormal" else ""
        unit = next(q.unit for q in post.model.observables if q.name == o)
        obs[o] = {"column": f"{o}_se", "median": float(np.median(se)), "max": float(np.max(se)), "sigma": sigma,
                  "unit": unit}
        notes.append({"check": "known_se", "status": "NOTE", "parameter": sigma,
                      "message": f"{o}: per-row standard errors from the dataset added in quadrature to {sigma} "
                                 f"({o}_se, median {np.median(se):.3g} {unit}{log}): {sigma} is the extra "
                                 "stroke-to-stroke scatter beyond them"})
    for c, r in post.covariate_se.items():
        largest = ("" if r["max_relative"] is None
                   else f"; largest relative standard error {r['max_relative']:.2g} (row {r['row']})")
        notes.append({"check": "known_se", "status": "NOTE", "parameter": None,
                      "message": f"{c}: standard errors in the dataset ({r['column']}) reported, not modelled: {c} "
                                 f"is treated as known (errors-in-variables not modelled){largest}"})
    return {"observables": obs, "covariates": dict(post.covariate_se), "notes": notes}


def _derived_group(post, theta, nw, nd, dims, coords, attrs):
    """The card's ``[derived]`` quantities on every draw: one value per level of its ``over``
    columns (and of the columns parameters are split by), as a ``derived`` group."""
    spec = post.model.derived
    if not spec:
        return {}
    attrs["derived"] = json.dumps({"function": spec["function"], "quantities": dict(spec["quantities"])})
    cols = list(spec["over"]) + [c for cs in post.split.values() for c in cs if c not in spec["over"]]
    labels = level_labels(post.dataset.frame, cols, post.dataset) if cols else ["all"] * post.n
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


@lru_cache(maxsize=1)
def versions():
    """The versions of skinfit and the libraries its numbers depend on (recorded with every fit)."""
    out = {}
    for pkg in _VERSIONED:
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out
