"""Names that tell fits apart: two runs of one model on one dataset differ in their options.

``compare`` and ``report`` name a fit by its model id; when several fits share model and
dataset, each is labelled by the options that differ between them (seed, prior file, split,
noise model, constants, walkers, the data's sha256 when the dataset changed), e.g.
``electroadhesion [seed 2]`` and ``electroadhesion [seed 3]``, or
``electroadhesion [priors electroadhesion_uniform]``. Fits whose options are the same are
told apart by their identity: the file each was read from (the shortest tail of its path that
differs, ``[file a/fit.nc]``), else the sha256 of its content (``[content 1a2b3c4d]``); only
the same fit given twice is numbered ``#2``, ``#3``.
"""

import json
from pathlib import Path

__all__ = ["run_options", "run_labels"]


def run_options(fit):
    """The options of a fit that can differ between runs on one dataset, as short texts keyed
    ``seed``, ``priors``, ``walkers``, ``split P``, ``noise O``, each constant's name and
    ``dataset`` and ``data`` (its id and the first 8 hex digits of its sha256)."""
    attrs = fit.attrs
    setup = json.loads(attrs.get("setup", "{}"))
    seed = attrs.get("seed", -1)
    sampler = json.loads(attrs.get("sampler", "{}"))
    out = {"seed": "none" if seed == -1 else str(seed),
           "priors": f"{attrs.get('priors_id', '?')} ({str(attrs.get('priors_sha256', ''))[:8]})",
           "walkers": str(sampler.get("nwalkers", "")), "dataset": str(attrs.get("dataset_id", "")),
           "data": str(attrs.get("dataset_sha256", ""))[:8]}
    out |= {f"split {p}": "+".join(c) for p, c in sorted(setup.get("split", {}).items())}
    out |= {f"noise {o}": k for o, k in sorted(setup.get("noise", {}).items())}
    out |= {k: f"{v:g}" for k, v in sorted(setup.get("constants", {}).items())}
    return out


def run_labels(fits, *, names=None, number_identical=True):
    """One label per fit: its model id, with the options that differ from the other fits of the
    same model on the same dataset (``model [option value, ...]``); fits whose options are the
    same with their file (``names``, one path or None per fit; default each fit's ``path``, the
    file :func:`skinfit.load_fit` read) or else their content's sha256; fits of the same
    content from the same file (the same fit twice) numbered ``#2``, ``#3`` unless
    ``number_identical`` is false."""
    fits = list(fits)
    names = [getattr(f, "path", None) for f in fits] if names is None else list(names)
    labels = [f.attrs["model_id"] for f in fits]
    for members in _same_data(fits):
        if len(members) < 2:
            continue
        options = [run_options(fits[i]) for i in members]
        keys = list(dict.fromkeys(k for o in options for k in o))
        options = [{k: o.get(k, "none") for k in keys} for o in options]
        differ = [k for k in keys if len({o[k] for o in options}) > 1]
        for i, o in zip(members, options):
            if differ:
                shown = [f"{k} {o[k].split(' (')[0]}" if k == "priors" and len({p['priors'].split(' (')[0]
                                                                                   for p in options}) > 1
                         else f"{k} {o[k]}" for k in differ]
                labels[i] = f"{labels[i]} [{', '.join(shown)}]"
        _identify(fits, names, labels, members)
        seen = {}
        for i in members if number_identical else ():  # the same fit twice: numbered
            seen[labels[i]] = seen.get(labels[i], 0) + 1
            if seen[labels[i]] > 1:
                labels[i] = f"{labels[i]} #{seen[labels[i]]}"
    return labels


def _same_data(fits):
    """The indices of ``fits`` in groups of one model on one dataset: fits of a model linked
    when they share the dataset's id or its sha256 (the same data read from another file, or
    the dataset edited), in order of first appearance."""
    parent = list(range(len(fits)))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    first = {}
    for i, f in enumerate(fits):
        for key in ("dataset_id", "dataset_sha256"):
            k = (f.attrs["model_id"], key, f.attrs.get(key))
            if k in first:
                parent[root(i)] = root(first[k])
            else:
                first[k] = i
    groups = {}
    for i in range(len(fits)):
        groups.setdefault(root(i), []).append(i)
    return list(groups.values())


def _identify(fits, names, labels, members):
    """Fits of ``members`` whose labels are still the same: their file's path (its shortest
    differing tail) appended, else their content's sha256 (first 8 hex digits)."""
    same = {}
    for i in members:
        same.setdefault(labels[i], []).append(i)
    for twins in (t for t in same.values() if len(t) > 1):
        paths = [Path(names[i]).resolve() if names[i] is not None else None for i in twins]
        if None not in paths and len(set(paths)) > 1:
            for i, tail in zip(twins, _tails(paths)):
                labels[i] = _append(labels[i], f"file {tail}")
            continue
        hashes = [fits[i].content_hash() if hasattr(fits[i], "content_hash") else None for i in twins]
        if None not in hashes and len(set(hashes)) > 1:
            width = next(w for w in (8, 12, 16, 64) if len({h[:w] for h in hashes}) == len(set(hashes)))
            for i, h in zip(twins, hashes):
                labels[i] = _append(labels[i], f"content {h[:width]}")


def _append(label, text):
    """``model [a, b]`` + ``c`` -> ``model [a, b, c]``; ``model`` + ``c`` -> ``model [c]``."""
    return f"{label[:-1]}, {text}]" if label.endswith("]") else f"{label} [{text}]"


def _tails(paths):
    """The shortest tails of ``paths`` (``fit.nc``, ``a/fit.nc``, ...) that tell the distinct
    paths apart; the same path gives the same tail."""
    for k in range(1, max(len(p.parts) for p in paths) + 1):
        tails = [Path(*p.parts[-k:]).as_posix() for p in paths]
        if len(set(tails)) == len(set(paths)):
            return tails
    return [p.as_posix() for p in paths]
