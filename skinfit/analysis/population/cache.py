"""A population result kept by the content of its inputs (``population(cache=...)``): read
back instead of sampled when the fits, the settings and skinfit's code are the same."""

from __future__ import annotations

import hashlib
import io
import json
import zipfile

import numpy as np

from skinfit.analysis.population.result import PopulationResult
from skinfit.inference.checkpoint import replace_atomic
from skinfit.io.paths import code_hash
from skinfit.io.shipped import shipped_physics
from skinfit.results.fit import plain_json

__all__ = ["cacheable", "cache_key", "write_cache", "read_cache"]


def cacheable(fit):
    """True when ``fit`` is of a shipped model card, unchanged since the fit, whose functions are
    all skinfit's own (:func:`skinfit.io.shipped.shipped_physics`): a population computed from
    it then follows from its content and skinfit's source, and may be kept."""
    return shipped_physics(fit.model_id, fit.attrs.get("model_sha256"))


def cache_key(fits, settings):
    """sha256 of a population's inputs: subjects (label, fit content), settings, skinfit's code
    and the numpy, scipy and arviz-stats (its diagnostics) versions (:func:`skinfit.io.paths.code_hash`)."""
    doc = {"format": 1, "subjects": [[label, f.content_hash()] for label, f in fits.items()],
           "settings": settings, "code": code_hash(("numpy", "scipy", "arviz-stats"))}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def write_cache(path, key, result):
    """Write ``result`` with its input ``key`` into ``path`` (npz, no pickle), atomically."""
    meta = {"key": key, "model_id": result.model_id, "parameters": result.parameters, "families": result.families,
            "subjects": result.subjects, "hyperpriors": result.hyperpriors, "sampler": result.sampler,
            "warnings": result.warnings, "contraction": result.contraction, "corr": result.corr is not None,
            "inputs": result.inputs, "diagnostics": result.diagnostics().to_dict("records")}
    arrays = {"mu": result.mu, "sd": result.sd, "shrunk": result.shrunk,
              **({"corr": result.corr} if result.corr is not None else {}),
              **{f"separate_{i}": result.separate[s] for i, s in enumerate(result.subjects)}}
    buf = io.BytesIO()
    np.savez(buf, meta=np.array(json.dumps(meta, default=plain_json)), **arrays)
    replace_atomic(path, buf.getvalue())


def read_cache(path, key):
    """The result kept in ``path`` for input ``key``; None when absent, of other inputs or
    unreadable (a partial or corrupt file: sampled again and rewritten)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            if meta.get("key") != key:
                return None
            hyper = dict(meta["hyperpriors"])
            if "_bounds" in hyper:
                hyper["_bounds"] = {k: tuple(v) for k, v in hyper["_bounds"].items()}
            result = PopulationResult(meta["model_id"], meta["parameters"], meta["families"], meta["subjects"],
                                      z["mu"], z["sd"], z["corr"] if meta["corr"] else None, z["shrunk"],
                                      {s: z[f"separate_{i}"] for i, s in enumerate(meta["subjects"])}, hyper,
                                      meta["sampler"], meta["warnings"], meta["contraction"], meta["inputs"])
            result._diagnostics = meta["diagnostics"]
            return result
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):
        return None
