"""A fit's pointwise groups (``log_likelihood``, ``posterior_predictive``: a value per posterior
draw and data row each), computed from its posterior draws, its data and one seed.

They are nine tenths of a fit's bytes and a pure function of what the rest of the file holds:
the draws (``posterior``), the data (``observed_data``, ``constant_data``, under the file's
checksums), the model card and prior file (root attributes) and the seed and thinning recorded
in the root attribute :data:`RECIPE`. :meth:`skinfit.results.fit.Fit.save` therefore writes
the recipe, not the groups, and a loaded fit computes them again on first use
(:class:`Recomputed`), the same bits as when the fit was made; the recipe's sums of each
variable (:func:`fingerprint`) are checked against the groups computed again, so a skinfit
whose physics gives other numbers refuses the file instead of mixing two results.
bench/results/run_size.md has the sizes and times behind this.

Built with xarray alone (no ArviZ tree builder): a saved fit's predictive check reads them in
a report's figure worker that does not import arviz_base.
"""

import json
import tomllib

import numpy as np
import xarray as xr

from skinfit.errors import InputError
from skinfit.io.labels import annotate
from skinfit.io.registry import BUILTIN

__all__ = ["RECIPE", "pointwise_tree", "fingerprint", "make_recipe", "recomputable", "theta_of", "Recomputed"]

#: Root attribute of a fit whose pointwise groups are computed from its draws (JSON: ``seed``,
#: four integers; ``every`` and ``walker_step``, the thinning; ``sums``, :func:`fingerprint`).
RECIPE = "pointwise"
#: Relative tolerance of the check of groups computed again against the recipe's sums: far
#: above the rounding of a sum of float64 values, far below any change of a model's numbers.
_RTOL = 1e-9


def pointwise_tree(post, theta, nwalkers, ndraws, seed, every=1, walker_step=1):
    """The ``log_likelihood`` and ``posterior_predictive`` groups of posterior draws ``theta``
    (nwalkers * ndraws, d, natural units, walker-major) of Posterior ``post`` as a DataTree,
    each variable (chain, draw, obs_id), float64, with units; with ``every`` or
    ``walker_step`` > 1 on every ``every``-th draw of every ``walker_step``-th walker only (the
    kept ``chain`` / ``draw`` coordinates). The predictive draws come from
    ``numpy.random.default_rng(seed)``."""
    d = theta.shape[1]
    kept = theta.reshape(nwalkers, ndraws, d)[::walker_step, ::every].reshape(-1, d)
    ll, simulated = post.replicate(kept, np.random.default_rng(seed))
    chains, draws = np.arange(nwalkers)[::walker_step], np.arange(ndraws)[::every]
    shape, dims = (len(chains), len(draws), post.n), ("chain", "draw", "obs_id")
    coords = {"chain": chains, "draw": draws, "obs_id": np.arange(post.n)}
    tree = xr.DataTree.from_dict({
        "log_likelihood": xr.Dataset({o: (dims, v.reshape(shape)) for o, v in ll.items()}, coords=coords),
        "posterior_predictive": xr.Dataset({o: (dims, v.reshape(shape)) for o, v in simulated.items()},
                                           coords=coords)})
    return annotate(tree, post)


def fingerprint(tree):
    """{group: {variable: [sum, sum of absolute values]}} of the pointwise groups of ``tree``
    (float64 sums): what a recomputation is checked against."""
    out = {}
    for group in ("log_likelihood", "posterior_predictive"):
        ds = tree[group].to_dataset()
        out[group] = {v: [float(np.sum(ds[v].values, dtype=float)), float(np.sum(np.abs(ds[v].values), dtype=float))]
                      for v in ds.data_vars}
    return out


def make_recipe(seed, every, walker_step, tree):
    """The :data:`RECIPE` attribute (JSON text) of pointwise groups ``tree`` computed by
    :func:`pointwise_tree` with ``seed`` (four integers), ``every`` and ``walker_step``."""
    return json.dumps({"seed": [int(s) for s in np.asarray(seed).ravel()], "every": int(every),
                       "walker_step": int(walker_step), "sums": fingerprint(tree)})


def recomputable(tree):
    """True when the pointwise groups of ``tree`` (a fit's) can be left out of its file: it has
    their :data:`RECIPE` and its model's forward function ships with skinfit
    (:data:`skinfit.io.registry.BUILTIN`), so that wherever skinfit reads the file it can compute
    them again. A plug-in's or a user's model may be missing where the file is read (a report
    on another machine): its fit keeps them."""
    if RECIPE not in tree.attrs:
        return False
    try:
        forward = tomllib.loads(tree.attrs["model_card"]).get("forward")
    except (KeyError, TypeError, tomllib.TOMLDecodeError):
        return False
    return forward in BUILTIN["forward"]


def theta_of(post, posterior):
    """The draws of Dataset ``posterior`` (a fit's ``posterior`` group) as (chain * draw, d) in
    the slot order of Posterior ``post`` (natural units, walker-major): the array the fit's
    pointwise groups were computed from."""
    cols = []
    for slot in post.slots:
        da = posterior[slot.base]
        if slot.level is not None:
            dim = next(d for d in da.dims if d not in ("chain", "draw"))
            da = da.sel({dim: slot.level})
        cols.append(da.transpose("chain", "draw").values.reshape(-1))
    return np.column_stack(cols)


class Recomputed:
    """The pointwise groups of a fit loaded from ``path`` whose file holds their :data:`RECIPE`
    instead: computed by :meth:`read` from the Posterior ``posterior()`` gives (a callable, so
    that the fit rebuilds it once for everything) and checked against the recipe's sums."""

    names = ("log_likelihood", "posterior_predictive")

    def __init__(self, path, posterior):
        self.path = path
        self.posterior = posterior

    def read(self, tree):
        """``tree`` with the pointwise groups computed and put in ArviZ's order (after
        ``sample_stats``); InputError, one line naming the file, when they differ from the
        recipe's sums (this skinfit's model gives other numbers than the one that made the fit)."""
        recipe = json.loads(tree.attrs[RECIPE])
        post = self.posterior()
        posterior = tree["posterior"].to_dataset()
        nwalkers, ndraws = posterior.sizes["chain"], posterior.sizes["draw"]
        try:
            extra = pointwise_tree(post, theta_of(post, posterior), nwalkers, ndraws, recipe["seed"],
                                   recipe["every"], recipe["walker_step"])
        except ValueError as exc:  # a draw outside the support of this skinfit's model
            raise InputError(self.path, f"its pointwise groups cannot be computed again ({exc})") from None
        _check_sums(self.path, fingerprint(extra), recipe["sums"], tree.attrs.get("versions", "{}"))
        first = [n for n in tree.children if n in ("posterior", "prior", "sample_stats")]
        order = [(tree, n) for n in first] + [(extra, n) for n in self.names]
        order += [(tree, n) for n in tree.children if n not in first]
        return xr.DataTree.from_dict({"/": tree.to_dataset(inherit=False)}  # a group's own groups kept
                                     | {node.relative_to(source): node.to_dataset(inherit=False)
                                        for source, n in order for node in source[n].subtree})


def _check_sums(path, found, expected, versions):
    for group, variables in expected.items():
        for var, (total, scale) in variables.items():
            got = found.get(group, {}).get(var)
            if got is None or abs(got[0] - total) > _RTOL * max(scale, 1e-300):
                made_with = json.loads(versions).get("skinfit", "another version")
                raise InputError(path, f"its {group} ({var}) computed again from its draws differs from when it "
                                       f"was fitted (skinfit {made_with}): this skinfit's model gives other numbers; "
                                       "fit again, or read it with the skinfit that made it")
