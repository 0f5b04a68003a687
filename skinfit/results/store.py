"""A fit's tree saved as netCDF-4 (HDF5) and read back, with its checksums
(:mod:`skinfit.io.integrity`) written with it and checked on every read.

:func:`write_tree` writes atomically (temporary file + rename) with xarray; :func:`read_tree`
reads, with h5netcdf, the groups but those named ``later`` (a fit's pointwise groups, most of a
file an earlier skinfit wrote; :mod:`skinfit.results.pointwise` computes them for the files
written now), which :class:`StoredGroups` reads from the same file when they are first used. Each group
becomes an xarray Dataset as ``xarray.open_datatree`` gives it (:func:`decoded`); a file of
another layout (variables at its root, nested groups) is read whole by ``xarray.open_datatree``.
"""

import errno
import os
import shutil
import sys
from contextlib import nullcontext
from pathlib import Path

import h5netcdf
import xarray as xr

from skinfit.errors import InputError
from skinfit.inference.checkpoint import replace_atomic
from skinfit.io import integrity
from skinfit.io.arguments import check_input_file, check_path

__all__ = ["write_tree", "read_tree", "fit_file", "StoredGroups", "decoded"]

#: What reading a damaged or foreign file can raise (HDF5's errors through h5py, numpy's for a
#: corrupted shape, decoding errors): each becomes one line naming the file.
_UNREADABLE = (OSError, ValueError, KeyError, TypeError, IndexError, RuntimeError, AttributeError, OverflowError,
               MemoryError)


def write_tree(tree, path):
    """Write DataTree ``tree`` to ``path`` (a checked output file whose folder exists) as
    netCDF-4, with the sha256 of each group and of the root attributes in its root attributes
    (:func:`skinfit.io.integrity.stamp`: ``tree`` gains them too) and of its bytes at its end
    (:func:`skinfit.io.integrity.seal`). Atomic: a failure leaves the previous file. Returns
    ``path``."""
    path = Path(path)
    # HDF5 writes into memory, never onto a disk that may fill (on a full disk it crashed the
    # process at exit, rc 139); the bytes go out by plain writes, so a full or read-only disk
    # is an OSError with the previous file in place
    dask = sys.modules.get("dask")  # in a Dask worker xarray would take a distributed lock named by the target
    integrity.stamp(tree)  # the tree in memory as it is read back: with its checksums
    with dask.config.set(scheduler="synchronous") if dask is not None else nullcontext():
        data = integrity.seal(tree.to_netcdf(engine="h5netcdf"))  # and the sha256 of its bytes
    free = shutil.disk_usage(path.parent).free
    if free < len(data) + (1 << 20):
        raise OSError(errno.ENOSPC, f"no space to save the fit: {len(data) / 2**20:.1f} MiB needed, "
                                    f"{free / 2**20:.1f} MiB free", str(path))
    replace_atomic(path, data)  # a unique temp file per writer; a killed writer's is removed by the next run
    return path


def fit_file(path) -> Path:
    """The file of a saved fit: ``path`` itself, or ``path/fit.nc`` for a run directory (a
    regular file: a FIFO or a device is refused before HDF5 opens it and waits on it)."""
    path = Path(check_path(path, "load_fit", None, "the path of a fit.nc or of its run directory"))
    if path.is_dir():
        path = path / "fit.nc"
    if not path.exists():
        raise InputError(path, "no such fit file")
    return check_input_file(path, "fit file")


def read_tree(path, later=()):
    """(tree, stored) of the saved fit at ``path``: the tree without the groups named in
    ``later``, checked against the file's checksums, and the :class:`StoredGroups` that reads
    those (None when the file has none of them). InputError, one line naming the file, for a
    damaged or unreadable file."""
    try:
        stored = StoredGroups(path, later)
        tree = stored.read_light()
    except InputError:
        raise
    except _UNREADABLE as exc:
        raise InputError(path, f"not a readable skinfit result ({_one_line(exc)})") from None
    return tree, (stored if stored.names else None)


def _one_line(exc):
    return f"{type(exc).__name__}: {' '.join(str(exc).split())}"[:300]


class StoredGroups:
    """The groups named ``later`` of a saved fit, left in its file until first used; the file is
    identified by device, inode, size and modification time when first read."""

    def __init__(self, path, later=()):
        self.path = Path(path)
        self.later = tuple(later)
        self.identity = self._identity()
        self.names = []
        self.order = []
        self.sealed = False  # its bytes checked against the sha256 they end with (skinfit.io.integrity)
        self.record = None  # else its content's checksums, checked as each group is read

    def _identity(self):
        st = os.stat(self.path)
        return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns

    def read_light(self):
        """The tree without the groups of ``later`` (those in the file listed in ``names``)."""
        self.sealed = integrity.check_file(self.path)  # its bytes, before HDF5 parses any of them
        with h5netcdf.File(self.path, "r", decode_vlen_strings=True) as h:
            order = list(h.groups)  # names only: a group's metadata is read when it is opened
            light = {g: h.groups[g] for g in order if g not in self.later}
            if h.variables or any(g.groups for g in light.values()):
                return self._whole()  # not Fit.save's layout
            attrs = _attributes(h)
            nodes = {g: decoded(group) for g, group in light.items()}
        self.record = integrity.take(self.path, attrs, order, sealed=self.sealed)  # else its content's checksums
        integrity.verify(self.path, self.record, groups=nodes)
        self.order, self.names = order, [g for g in order if g in self.later]
        return xr.DataTree.from_dict({"/": xr.Dataset(attrs=attrs)} | nodes)

    def _whole(self):
        """The whole tree of a file of another layout (``xarray.open_datatree``), checked."""
        with xr.open_datatree(self.path, engine="h5netcdf") as tree:
            tree = tree.load()
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
        try:
            with h5netcdf.File(self.path, "r", decode_vlen_strings=True) as h:
                groups = {g: h.groups[g] for g in self.names}
                if any(group.groups for group in groups.values()):
                    raise InputError(self.path, f"groups inside {', '.join(g for g in groups if groups[g].groups)}: "
                                                "not a fit file skinfit writes")
                extra = {g: decoded(group) for g, group in groups.items()}
        except InputError:
            raise
        except _UNREADABLE as exc:
            raise InputError(self.path, f"its pointwise groups cannot be read ({_one_line(exc)})") from None
        integrity.verify(self.path, self.record, groups=extra)
        nodes = {n: tree[n].to_dataset(inherit=False) for n in tree.children} | extra
        order = [g for g in self.order if g in nodes] + [g for g in nodes if g not in self.order]
        return xr.DataTree.from_dict({"/": tree.to_dataset(inherit=False)} | {n: nodes[n] for n in order})


def decoded(group):
    """One group of an open ``h5netcdf.File`` as an xarray Dataset, decoded as
    ``xarray.open_datatree`` decodes it: its variables' values read, text attributes as str,
    CF conventions applied by ``xarray.decode_cf``."""
    variables = {k: xr.Variable(v.dimensions, v[...], attrs=_attributes(v)) for k, v in group.variables.items()}
    return xr.decode_cf(xr.Dataset(variables, attrs=_attributes(group)))


def _attributes(obj):
    """The attributes of an h5netcdf group or variable, bytes decoded as UTF-8 (as xarray's
    h5netcdf backend gives them; a fill value stays as stored)."""
    return {k: v.decode() if isinstance(v, bytes) and k not in ("_FillValue", "missing_value") else v
            for k, v in obj.attrs.items()}
