"""Quantities that depend on the covariates alone, computed once per data set.

A forward function is called thousands of times per fit on the same rows. What it computes
from the covariates alone (masks, fills, logarithms, quadrature nodes) is cached here, keyed by
the arrays' values rather than their identity: a caller who changes an array in place gets a
fresh computation. The results are read-only, so no caller can change them for the next one.
"""

from functools import lru_cache, wraps

import numpy as np

__all__ = ["by_value"]


def by_value(func):
    """Cache ``func(*arrays, *scalars)`` by the values of the float ``arrays`` (broadcast to one
    shape) and the hashable ``scalars``.  ``func`` must return a tuple of arrays (made read-only)."""

    @lru_cache(maxsize=32)
    def cached(shape, blobs, scalars):
        arrays = [np.frombuffer(b).reshape(shape) for b in blobs]
        out = func(*arrays, *scalars)
        for a in out:
            a.flags.writeable = False
        return out

    @wraps(func)
    def wrapper(*arrays, scalars=()):
        arrays = [np.asarray(a, dtype=float) for a in arrays]
        shape = arrays[0].shape
        if any(a.shape != shape for a in arrays):
            arrays = np.broadcast_arrays(*arrays)
            shape = arrays[0].shape
        return cached(shape, tuple(a.tobytes() for a in arrays), tuple(scalars))  # tobytes: C order

    wrapper.cache_clear = cached.cache_clear
    return wrapper
