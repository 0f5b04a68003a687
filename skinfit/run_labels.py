"""Names that tell fits apart: two runs of one model on one dataset differ in their options.

``compare`` and ``report`` name a fit by its model id; when several fits share model and data,
each is labelled by the options that differ between them (seed, prior file, split, noise model,
constants, ESS target), e.g. ``electroadhesion [seed 2]`` and ``electroadhesion [seed 3]``, or
``electroadhesion [priors electroadhesion_uniform]``.  Identical runs get ``#2``, ``#3`` in compare.
"""

import json

__all__ = ["run_options", "run_labels"]


def run_options(fit):
    """The options of a fit that can differ between runs on one dataset, as short texts keyed
    ``seed``, ``priors``, ``walkers``, ``split P``, ``noise O`` and each constant's name."""
    attrs = fit.attrs
    setup = json.loads(attrs.get("setup", "{}"))
    seed = attrs.get("seed", -1)
    sampler = json.loads(attrs.get("sampler", "{}"))
    out = {"seed": "none" if seed == -1 else str(seed),
           "priors": f"{attrs.get('priors_id', '?')} ({str(attrs.get('priors_sha256', ''))[:8]})",
           "walkers": str(sampler.get("nwalkers", ""))}
    out |= {f"split {p}": "+".join(c) for p, c in sorted(setup.get("split", {}).items())}
    out |= {f"noise {o}": k for o, k in sorted(setup.get("noise", {}).items())}
    out |= {k: f"{v:g}" for k, v in sorted(setup.get("constants", {}).items())}
    return out


def run_labels(fits, *, number_identical=True):
    """One label per fit: its model id, with the options that differ from the other fits of the
    same model on the same data (``model [option value, ...]``); fits with identical options
    numbered ``#2``, ``#3`` unless ``number_identical`` is false (the report numbers its keys)."""
    fits = list(fits)
    labels = [f.attrs["model_id"] for f in fits]
    groups = {}
    for i, f in enumerate(fits):
        groups.setdefault((f.attrs["model_id"], f.attrs.get("dataset_sha256")), []).append(i)
    for members in groups.values():
        if len(members) < 2:
            continue
        options = [run_options(fits[i]) for i in members]
        keys = list(dict.fromkeys(k for o in options for k in o))
        options = [{k: o.get(k, "none") for k in keys} for o in options]
        differ = [k for k in keys if len({o[k] for o in options}) > 1]
        for n, (i, o) in enumerate(zip(members, options)):
            if differ:
                shown = [f"{k} {o[k].split(' (')[0]}" if k == "priors" and len({p['priors'].split(' (')[0]
                                                                                   for p in options}) > 1
                         else f"{k} {o[k]}" for k in differ]
                labels[i] = f"{labels[i]} [{', '.join(shown)}]"
        seen = {}
        for i in members if number_identical else ():  # identical options: number them
            seen[labels[i]] = seen.get(labels[i], 0) + 1
            if seen[labels[i]] > 1:
                labels[i] = f"{labels[i]} #{seen[labels[i]]}"
    return labels
