"""Reading raw recordings as a rig file describes them, by slices so long files stay bounded in
memory: MATLAB v7.3 and HDF5 through h5py (a slice reads only its samples), MATLAB v5 through
scipy.io.loadmat (the format cannot be sliced: the matrix is read whole), CSV through pandas
(read whole; its time column gives the sample rate).

A :class:`Trial` is one recording: a .mat or .csv file, or one group ``/<group>/<name>`` of an
HDF5 file (datasets named after the channels, ``sample_rate_hz`` attribute on the group, the
file, or a dataset sampled at its own rate).
"""

import math
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import scipy.io

from skinfit.errors import InputError
from skinfit.io.paths import display
from skinfit.io.recordings.rig import pattern_regex

__all__ = ["Trial", "open_trials", "trial_metadata"]

_MATLAB_HEADER = b"MATLAB 7.3"


@dataclass
class Trial:
    """One recording: ``read(channel, start, stop)`` gives the raw values of samples
    [start, stop) of ``channel`` at its own rate (``rate(channel)`` Hz, ``length(channel)`` samples)."""

    name: str
    file: Path
    base_rate: float
    attrs: dict = field(default_factory=dict)
    _reader: object = None

    def rate(self, channel):
        return self._reader.rate(channel) or self.base_rate

    def length(self, channel):
        return self._reader.length(channel)

    def read(self, channel, start, stop):
        start, stop = max(int(start), 0), min(int(stop), self.length(channel))
        if stop <= start:
            return np.zeros(0)
        return np.asarray(self._reader.read(channel, start, stop), dtype=float)

    @property
    def n(self):
        """Samples at the base rate (the shortest channel sampled at it)."""
        return min(self.length(c) for c in self._reader.base_channels())


class _Matrix:
    """A matrix with samples in rows (v5, CSV) or an HDF5 dataset with channels in rows (v7.3);
    ``columns`` maps each channel's name to its 0-based column."""

    def __init__(self, rig, data, transposed, where, columns=None):
        self.rig, self.data, self.transposed, self.where = rig, data, transposed, where
        self.columns = columns or {c.name: c.source for c in rig.channels}
        width = data.shape[0] if transposed else data.shape[1]
        for c in rig.channels:
            if self.columns[c.name] >= width:
                raise InputError(where, f"has {width} columns; channels.{c.name}.column = {self.columns[c.name]} "
                                 f"(0-based) is past them")
            if c.sample_rate:
                raise InputError(where, "a channel at its own sample rate needs its own dataset (HDF5)",
                                 field=f"channels.{c.name}.sample_rate")

    def rate(self, channel):
        return None

    def base_channels(self):
        return self.rig.channels

    def length(self, channel):
        return self.data.shape[1] if self.transposed else self.data.shape[0]

    def read(self, channel, start, stop):
        j = self.columns[channel.name]
        return self.data[j, start:stop] if self.transposed else self.data[start:stop, j]


class _Group:
    """An HDF5 trial group: a 1-D dataset per channel, or channels as columns of a 2-D dataset
    (``column = k``; its longer axis is taken for time, so a matrix MATLAB wrote transposed reads
    the same)."""

    def __init__(self, rig, group, rate, where):
        self.rig, self.group, self.base, self.where = rig, group, rate, where
        self.rows = {}  # channel name -> True when samples run along the dataset's first axis
        for c in rig.channels:
            d = group.get(c.source)
            found = ", ".join(k for k in group if isinstance(group[k], h5py.Dataset))
            field = f"channels.{c.name}.dataset"
            if not isinstance(d, h5py.Dataset) or d.ndim not in (1, 2):
                raise InputError(where, f"has no 1-D or 2-D dataset {c.source!r} (expected one of {found})",
                                 field=field)
            if (d.ndim == 2) != (c.column is not None):
                raise InputError(where, f"dataset {c.source!r} is {d.ndim}-D with shape {d.shape}: "
                                 + ("give its column (channels.NAME.column)" if d.ndim == 2
                                    else "a column applies to a 2-D dataset only"), field=field)
            if d.ndim == 2:
                self.rows[c.name] = d.shape[0] >= d.shape[1]
                width = d.shape[1] if self.rows[c.name] else d.shape[0]
                if c.column >= width:
                    raise InputError(where, f"dataset {c.source!r} has {width} channels; column {c.column} (0-based) "
                                     "is past them", field=f"channels.{c.name}.column")

    def rate(self, channel):
        d = self.group[channel.source]
        if channel.sample_rate:
            return channel.sample_rate
        if "sample_rate_hz" in d.attrs:
            return float(d.attrs["sample_rate_hz"])
        return None

    def base_channels(self):
        return [c for c in self.rig.channels if not self.rate(c) or self.rate(c) == self.base] or self.rig.channels

    def length(self, channel):
        return max(self.group[channel.source].shape)

    def read(self, channel, start, stop):
        d = self.group[channel.source]
        if d.ndim == 1:
            return d[start:stop]
        return d[start:stop, channel.column] if self.rows[channel.name] else d[channel.column, start:stop]


def _scalar(value):
    value = value.decode() if isinstance(value, bytes) else value
    if isinstance(value, np.ndarray) and value.size == 1:
        value = value.item()
    return value.item() if isinstance(value, np.generic) else value


def _hdf5_trials(rig, path, fh, where):
    root = fh.get(rig.group)
    if not isinstance(root, h5py.Group):
        raise InputError(where, f"has no group /{rig.group} (expected one group per trial under it)", field="group")
    trials = []
    for name in root:
        g = root[name]
        if not isinstance(g, h5py.Group):
            continue
        attrs = {k: _scalar(v) for k, v in g.attrs.items()}
        rate = attrs.pop("sample_rate_hz", None) or _scalar(fh.attrs.get("sample_rate_hz", 0)) or rig.sample_rate
        if not rate:
            raise InputError(f"{where}:/{rig.group}/{name}", "no sample rate (expected a sample_rate_hz attribute "
                             "or sample_rate in the rig file)")
        reader = _Group(rig, g, float(rate), f"{where}:/{rig.group}/{name}")
        trials.append(Trial(f"{Path(path).stem}/{name}", Path(path), float(rate),
                            {k: v for k, v in attrs.items() if isinstance(v, (str, int, float))}, reader))
    if not trials:
        raise InputError(where, f"/{rig.group} holds no trial groups")
    return trials


def _mat_trial(rig, path, where, handles):
    with open(path, "rb") as fh:
        head = fh.read(128)
    if head.startswith(_MATLAB_HEADER) or h5py.is_hdf5(path):  # v7.3: HDF5, MATLAB's column-major order
        fh = h5py.File(path, "r")
        handles.append(fh)
        data = fh.get(rig.variable)
        if not isinstance(data, h5py.Dataset) or data.ndim != 2:
            raise InputError(where, f"has no matrix {rig.variable!r} (found {', '.join(fh) or 'nothing'})",
                             field="variable")
        return Trial(Path(path).stem, Path(path), rig.sample_rate, {}, _Matrix(rig, data, True, where))
    try:
        found = scipy.io.loadmat(path, variable_names=[rig.variable])
    except (ValueError, NotImplementedError, OSError) as exc:
        raise InputError(where, f"not a MATLAB file scipy.io.loadmat reads ({exc})") from None
    data = found.get(rig.variable)
    if not isinstance(data, np.ndarray) or data.ndim != 2 or data.dtype.kind not in "fiu":
        names = [k for k in scipy.io.whosmat(path)]
        raise InputError(where, f"has no numeric matrix {rig.variable!r} (found {', '.join(n[0] for n in names)})",
                         field="variable")
    return Trial(Path(path).stem, Path(path), rig.sample_rate, {}, _Matrix(rig, data, False, where))


def _csv_trial(rig, path, where):
    try:
        frame = pd.read_csv(path, sep=rig.delimiter, comment="#")
    except (ValueError, pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise InputError(where, f"not a CSV pandas reads with delimiter {rig.delimiter!r} ({exc})") from None
    headers = list(frame.columns)

    def index(key, field):
        if isinstance(key, int):
            if key >= len(headers):
                raise InputError(where, f"has {len(headers)} columns; {field} = {key} (0-based) is past them")
            return key
        if key not in headers:
            raise InputError(where, f"has no column {key!r} (header: {', '.join(map(str, headers))})", field=field)
        return headers.index(key)

    cols = {c.name: index(c.source, f"channels.{c.name}.column") for c in rig.channels}
    data = frame.to_numpy(dtype=float)
    if not np.all(np.isfinite(data)):
        row = int(np.nonzero(~np.all(np.isfinite(data), axis=1))[0][0]) + 1
        raise InputError(where, "expected numbers in every column", row=row)
    rate = rig.sample_rate
    if rig.time_column is not None:
        t = data[:, index(rig.time_column, "time_column")]
        step = np.diff(t)
        if len(t) < 2 or np.any(step <= 0) or np.ptp(step) > 0.01 * np.median(step):
            raise InputError(where, "the time column is not uniformly spaced and increasing (expected one sample "
                             "rate; resample first)", field="time_column")
        rate = 1.0 / float(np.median(step))
    return Trial(Path(path).stem, Path(path), rate, {}, _Matrix(rig, data, False, where, cols))


def open_trials(rig, files, handles):
    """The trials of ``files`` (paths) as ``rig`` describes them; open HDF5 files are appended to
    ``handles`` (the caller closes them)."""
    trials = []
    for f in files:
        path = Path(f)
        where = display(path)
        if not path.is_file():
            raise InputError(where, "raw recording not found (expected a file)")
        if rig.format == "hdf5":
            if not h5py.is_hdf5(path):
                raise InputError(where, "not an HDF5 file (the rig file says format = \"hdf5\")", field="format")
            fh = h5py.File(path, "r")
            handles.append(fh)
            found = _hdf5_trials(rig, path, fh, where)
        elif rig.format == "mat":
            found = [_mat_trial(rig, path, where, handles)]
        else:
            found = [_csv_trial(rig, path, where)]
        for t in found:
            for k, v in t.attrs.items():  # an HDF5 attribute declared a quantity under [metadata]: to SI
                spec = rig.metadata.get(k)
                if spec and spec["unit"]:
                    if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                        raise InputError(where, f"attribute {k!r} of {t.name} is {v!r}; expected a number in "
                                         f"{spec['unit']}", field=f"metadata.{k}")
                    t.attrs[k] = float(v) * spec["factor"]
            t.attrs.update(trial_metadata(rig, path))
            if t.n < 2:
                raise InputError(where, "holds fewer than two samples")
        trials += found
    return trials


def trial_metadata(rig, path):
    """{name: value} from the file name ``pattern`` and the rig's constant metadata; quantities
    converted to SI (a ``100`` read for ``voltage`` with unit ``V`` is 100.0)."""
    out = {k: m["value"] for k, m in rig.metadata.items() if m["value"] is not None}
    if not rig.pattern:
        return out
    where = display(path)
    m = pattern_regex(rig.pattern).match(Path(path).name)
    if not m:
        raise InputError(where, f"file name does not match the rig's pattern {rig.pattern!r}", field="pattern")
    for name, text in m.groupdict().items():
        spec = rig.metadata.get(name)
        if spec and spec["unit"]:
            try:
                value = float(text.replace(",", ".")) * spec["factor"]
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                raise InputError(where, f"{{{name}}} is {text!r} in the file name; expected a number in "
                                 f"{spec['unit']}", field="pattern")
            out[name] = value
        else:
            out[name] = text
    return out
