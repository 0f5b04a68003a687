"""xarray without importing dask and pint until something uses them.

On the first array it builds, xarray imports dask.base (to ask whether the data are a dask
collection), dask.array and pint (for their ``Array`` and ``Quantity`` types, to tell such
arrays apart) whenever they are installed: 0.4-0.8 s of every command that reads or writes a
fit, none of which uses dask collections or pint quantities there. No object can be a dask
collection before dask is imported, a dask array before dask.array is, or a pint Quantity
before pint is, so until then the answers are "no" without importing anything; from then on
they are xarray's own.
"""

from __future__ import annotations

import sys

#: xarray's duck-array module name -> (the module defining the type, the type's name)
_TYPES = {"dask": ("dask.array", "Array"), "pint": ("pint", "Quantity")}


class _UntilImported:
    """Stands in for xarray's cached ``DuckArrayModule(name)`` (``type``, ``module``,
    ``version``, ``available``) until the module defining its type is imported; then, or on
    any other question, puts xarray's own in its place and answers from it."""

    def __init__(self, cache, name):
        self._cache, self._name = cache, name

    def _real(self):
        from xarray.namedarray.pycompat import DuckArrayModule

        real = DuckArrayModule(self._name)
        if real.available or sys.modules.get(self._name, ...) is not None:  # not blocked for a moment
            self._cache[self._name] = real  # (Fit.save: sys.modules["dask"] = None while it writes)
        return real

    @property
    def type(self):
        module, attr = _TYPES[self._name]
        if not hasattr(sys.modules.get(module), attr):  # not imported (or still importing)
            return ()
        return self._real().type

    def __getattr__(self, name):  # module, version, available: xarray's own (imports the module)
        return getattr(self._real(), name)


def _collection_check(original):
    """xarray's ``is_dask_collection``, answering False without importing dask while dask is
    not imported."""

    def is_dask_collection(x):
        return sys.modules.get("dask") is not None and original(x)

    is_dask_collection.deferred = True
    return is_dask_collection


def defer_imports():
    """Put :class:`_UntilImported` in xarray's duck-array cache for dask and pint, and
    :func:`_collection_check` in place of its ``is_dask_collection``, once per process. Where
    this xarray has no such names (or already looked a module up), it imports as before:
    slower, not different."""
    try:
        from xarray.namedarray import pycompat, utils
    except ImportError:  # an xarray laid out otherwise
        return
    cache = getattr(pycompat, "_cached_duck_array_modules", None)
    if isinstance(cache, dict) and hasattr(pycompat, "DuckArrayModule"):
        for name, (module, _) in _TYPES.items():
            if name not in cache and module not in sys.modules:
                cache[name] = _UntilImported(cache, name)
    check = getattr(utils, "is_dask_collection", None)
    if callable(check) and not getattr(check, "deferred", False):
        utils.is_dask_collection = _collection_check(check)
