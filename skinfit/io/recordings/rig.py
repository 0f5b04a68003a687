"""The rig file (TOML): every step from a lab's raw recordings to one row per stroke, stated so
a reader can repeat it.  Validated once into a frozen :class:`Rig` with every quantity in SI;
each error is one line naming the rig file and the key (``rig.toml: channels.normal_force.gain:
unit 'N/m' applied to a V channel gives ...``).  docs/from-your-rig.md explains each key.
"""

import hashlib
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skinfit.errors import InputError
from skinfit.io.paths import display
from skinfit.io.toml import read_toml, require
from skinfit.io.units import parse_unit

__all__ = ["Rig", "Channel", "Calibration", "load_rig", "FORMATS", "TOP_KEYS"]

FORMATS = ("mat", "hdf5", "csv")
TOP_KEYS = ("schema_version", "format", "variable", "group", "sample_rate", "time_column", "delimiter", "pattern",
            "metadata", "channels", "calibration", "filter", "strokes", "reject")
_CHANNEL_KEYS = ("column", "dataset", "unit", "gain", "bias", "sample_rate", "rectify", "output")
_FILTER_KEYS = ("lowpass", "order", "notch", "notch_q")
_STROKE_KEYS = ("speed_above", "normal_force_above", "trim", "min_duration", "position", "velocity", "normal")
_REJECT_KEYS = ("channel", "target", "tolerance")
_CALIBRATION_KEYS = ("inputs", "outputs", "matrix", "unit", "rotation")
_METADATA_KEYS = ("unit", "kind", "value")
_FORCE, _LENGTH, _VELOCITY = parse_unit("N").dims, parse_unit("m").dims, parse_unit("m/s").dims
_TIME, _FREQUENCY = parse_unit("s").dims, parse_unit("Hz").dims


@dataclass(frozen=True)
class Channel:
    """One recorded channel: ``source`` is its 0-based column (mat, csv) or dataset name (hdf5,
    csv header); SI value = (raw - bias) * ``factor``; ``dims`` the dimension after the gain."""

    name: str
    source: object
    unit: str
    factor: float
    dims: frozenset
    si_unit: str
    bias_first: float | None = None  # [s] mean of the first seconds subtracted
    bias_last: float | None = None  # [s] with bias_first: a drift linear between the two windows
    sample_rate: float | None = None  # [Hz] its own rate, when sampled slower than the others
    rectify: bool = False  # stroke means reported as magnitudes (a force whose sign follows the stroke)
    output: bool = True  # a column of the dataset (a raw position is not)
    column: int | None = None  # HDF5: the channel's column of a 2-D dataset (its longer axis is time)


@dataclass(frozen=True)
class Calibration:
    """A k x k calibration matrix (k = 3: a 3-axis force sensor; k = 6: forces and torques) from k
    input channels (SI) to k outputs (SI), the mounting rotation applied."""

    inputs: tuple
    outputs: tuple
    matrix: np.ndarray  # (k, k), SI; already rotated
    dims: tuple  # output dimensions
    si_units: tuple


@dataclass(frozen=True)
class Rig:
    """A validated rig file; every quantity in SI (Hz, s, N, m/s)."""

    path: str
    text: str
    sha256: str
    format: str
    variable: str | None
    group: str
    sample_rate: float | None
    time_column: object
    delimiter: str
    pattern: str | None
    metadata: dict  # name -> {"unit": str | None, "value": float | str | None, "factor": float}
    channels: tuple
    calibration: Calibration | None
    lowpass: float
    order: int
    notch: tuple
    notch_q: float
    speed_above: float
    normal_force_above: float
    trim: float
    min_duration: float
    position: str | None
    velocity: str | None
    normal: str
    reject: dict | None  # {"channel", "target" (SI float or metadata key), "tolerance"}

    def channel(self, name):
        for c in self.channels:
            if c.name == name:
                return c
        raise KeyError(name)

    @property
    def derived(self):
        """{name: (dims, si_unit)} of every signal after calibration (channels and matrix outputs)."""
        out = {c.name: (c.dims, c.si_unit) for c in self.channels
               if not (self.calibration and c.name in self.calibration.inputs)}
        if self.calibration:
            out.update({n: (d, u) for n, d, u in zip(self.calibration.outputs, self.calibration.dims,
                                                      self.calibration.si_units)})
        return out

    def settings(self):
        """The pipeline's settings as text lines (recorded in the dataset's provenance)."""
        notch = (", ".join(f"{f:g} Hz" for f in self.notch) + f" (Q {self.notch_q:g}, zero phase)") if self.notch \
            else "none"
        return [f"format {self.format}", f"lowpass {self.lowpass:g} Hz, Butterworth order {self.order}, zero phase "
                "(scipy.signal.sosfiltfilt)", f"notch {notch}",
                f"strokes: |v| > {self.speed_above:g} m/s and {self.normal} > {self.normal_force_above:g} N, "
                f"trim {self.trim:g} s at each end, kept window >= {self.min_duration:g} s",
                "standard error: within-window sd / sqrt(n_eff), n_eff = n / tau (1 - (2M + 1) / n), tau the "
                "integrated autocorrelation time (emcee.autocorr.integrated_time, c = 5, window M ~ 5 tau) of the "
                "window subsampled to 5x the low-pass cut-off; the bias's standard error added in quadrature",
                f"reject: {self.reject}" if self.reject else "reject: no rule"]


def _refuse_unknown(table, allowed, where, prefix):
    for key in table:
        if key not in allowed:
            raise InputError(where, f"unknown key (expected one of {', '.join(allowed)})", field=prefix + key)


def _si_unit(u):
    for text in ("N", "m", "m/s", "s", "Hz", "V", "N*m", "1", "Pa", "m^2"):
        if parse_unit(text).dims == u.dims:
            return text
    return u.name


def quantity(doc, key, dims, where, prefix="", default=..., what=""):
    """``key = { value = 20, unit = "mm/s" }`` in SI, its dimension checked against ``dims``."""
    spec = require(doc, key, dict, where, field_prefix=prefix, default=default)
    if spec is None or spec is default:
        return spec
    field = prefix + key
    _refuse_unknown(spec, ("value", "unit"), where, field + ".")
    value = require(spec, "value", float, where, field_prefix=field + ".")
    unit = _unit(require(spec, "unit", str, where, field_prefix=field + "."), where, field + ".unit")
    if dims is not None and unit.dims != dims:
        raise InputError(where, f"unit {unit.text!r} is a {unit.name}; expected {what or 'another dimension'}",
                         field=field + ".unit")
    if not math.isfinite(value) or value < 0:
        raise InputError(where, f"expected a finite value >= 0 (got {value!r})", field=field + ".value")
    return value * unit.factor


def _unit(text, where, field):
    try:
        return parse_unit(text)
    except ValueError as exc:
        raise InputError(where, str(exc), field=field) from None


def _channel(name, spec, fmt, where):
    prefix = f"channels.{name}."
    if not isinstance(spec, dict):
        raise InputError(where, "expected a table (column = ..., unit = ...)", field=prefix.rstrip("."))
    _refuse_unknown(spec, _CHANNEL_KEYS, where, prefix)
    column = None
    if fmt == "hdf5":
        source = require(spec, "dataset", str, where, field_prefix=prefix, default=name)
        column = require(spec, "column", int, where, field_prefix=prefix, default=None)
        if column is not None and column < 0:
            raise InputError(where, f"expected a 0-based column number >= 0 (got {column!r})", field=prefix + "column")
    else:
        source = require(spec, "column", (int, str) if fmt == "csv" else int, where, field_prefix=prefix)
        if isinstance(source, int) and (isinstance(source, bool) or source < 0):
            raise InputError(where, f"expected a 0-based column number >= 0 (got {source!r})", field=prefix + "column")
    unit_text = require(spec, "unit", str, where, field_prefix=prefix)
    raw = _unit(unit_text, where, prefix + "unit")
    gain = require(spec, "gain", dict, where, field_prefix=prefix, default=None)
    if gain is None:
        out, factor = raw, raw.factor
    else:
        _refuse_unknown(gain, ("value", "unit"), where, prefix + "gain.")
        value = require(gain, "value", float, where, field_prefix=prefix + "gain.")
        gunit = require(gain, "unit", str, where, field_prefix=prefix + "gain.")
        _unit(gunit, where, prefix + "gain.unit")
        out = _unit(f"{unit_text}*{gunit}", where, prefix + "gain.unit")
        if not (math.isfinite(value) and value != 0):
            raise InputError(where, f"expected a finite non-zero gain (got {value!r})", field=prefix + "gain.value")
        factor = value * out.factor
    bias = require(spec, "bias", dict, where, field_prefix=prefix, default={})
    _refuse_unknown(bias, ("first", "last"), where, prefix + "bias.")
    first = quantity(bias, "first", _TIME, where, prefix + "bias.", None, "a time (e.g. s)")
    last = quantity(bias, "last", _TIME, where, prefix + "bias.", None, "a time (e.g. s)")
    if last is not None and first is None:
        raise InputError(where, "a drift correction needs bias.first too (the bias is linear between the two "
                         "windows)", field=prefix + "bias.last")
    rate = quantity(spec, "sample_rate", _FREQUENCY, where, prefix, None, "a frequency (e.g. Hz)")
    if rate is not None and rate <= 0:
        raise InputError(where, "expected a sample rate > 0", field=prefix + "sample_rate")
    return Channel(name, source, unit_text, float(factor), out.dims, _si_unit(out), first, last, rate,
                   require(spec, "rectify", bool, where, field_prefix=prefix, default=False),
                   require(spec, "output", bool, where, field_prefix=prefix, default=True), column)


def _calibration(doc, channels, where):
    spec = require(doc, "calibration", dict, where, default=None)
    if spec is None:
        return None
    p = "calibration."
    _refuse_unknown(spec, _CALIBRATION_KEYS, where, p)
    inputs = require(spec, "inputs", list, where, field_prefix=p)
    outputs = require(spec, "outputs", list, where, field_prefix=p)
    by_name = {c.name: c for c in channels}
    k = len(inputs)
    if k not in (3, 6) or len(outputs) != k or not all(isinstance(n, str) for n in inputs + outputs):
        raise InputError(where, "expected as many input channel names as output names, three (a 3-axis force sensor) "
                         "or six (forces and torques)",
                         field=p + "inputs")
    for n in inputs:
        if n not in by_name:
            raise InputError(where, f"names channel {n!r}, not under [channels] (expected one of "
                             f"{', '.join(by_name)})", field=p + "inputs")
    units = {by_name[n].unit for n in inputs}
    if len(units) > 1 or any(by_name[n].factor != parse_unit(by_name[n].unit).factor for n in inputs):
        raise InputError(where, "the inputs must share one unit and have no gain (the matrix is the gain)",
                         field=p + "inputs")
    matrix = require(spec, "matrix", list, where, field_prefix=p)
    try:
        m = np.array(matrix, dtype=float)
    except (TypeError, ValueError):
        m = np.zeros(0)
    if m.shape != (k, k) or not np.all(np.isfinite(m)):
        raise InputError(where, f"expected a {k}x{k} matrix of numbers (rows: outputs, columns: inputs)",
                         field=p + "matrix")
    row_units = require(spec, "unit", (str, list), where, field_prefix=p)
    row_units = [row_units] * k if isinstance(row_units, str) else row_units
    if len(row_units) != k or not all(isinstance(u, str) for u in row_units):
        raise InputError(where, f"expected one unit or {k} (one per output row)", field=p + "unit")
    in_unit = units.pop()
    parsed = [_unit(f"{in_unit}*{u}", where, p + "unit") for u in row_units]
    scale = np.array([u.factor for u in parsed]) / parse_unit(in_unit).factor
    m = m * scale[:, None]
    rotation = require(spec, "rotation", list, where, field_prefix=p, default=None)
    if rotation is not None:
        try:
            r = np.array(rotation, dtype=float)
        except (TypeError, ValueError):
            r = np.zeros(0)
        if r.shape != (3, 3) or not np.allclose(r @ r.T, np.eye(3), atol=1e-6):
            raise InputError(where, "expected a 3x3 rotation matrix (orthonormal rows)", field=p + "rotation")
        block = np.kron(np.eye(k // 3), r)  # forces (and torques) rotated alike
        m = block @ m
    return Calibration(tuple(inputs), tuple(outputs), m, tuple(u.dims for u in parsed),
                       tuple(_si_unit(u) for u in parsed))


def _metadata(doc, where):
    table = require(doc, "metadata", dict, where, default={})
    out = {}
    for name, spec in table.items():
        prefix = f"metadata.{name}."
        if not isinstance(spec, dict):
            raise InputError(where, "expected a table (unit = ..., or kind = \"category\")", field=f"metadata.{name}")
        _refuse_unknown(spec, _METADATA_KEYS, where, prefix)
        kind = require(spec, "kind", str, where, field_prefix=prefix, default="quantity" if "unit" in spec
                       else "category")
        if kind not in ("quantity", "category"):
            raise InputError(where, f"expected 'quantity' or 'category' (got {kind!r})", field=prefix + "kind")
        unit = require(spec, "unit", str, where, field_prefix=prefix) if kind == "quantity" else None
        parsed = _unit(unit, where, prefix + "unit") if unit else None
        value = require(spec, "value", (str, float) if kind == "category" else float, where, field_prefix=prefix,
                        default=None)
        out[name] = {"unit": unit, "si_unit": _si_unit(parsed) if parsed else None,
                     "factor": parsed.factor if parsed else 1.0,
                     "value": value * parsed.factor if parsed and value is not None else value}
    return out


def pattern_regex(pattern):
    """The regular expression of a file-name ``pattern`` (``{subject}_{voltage}V_{trial}.mat``):
    each ``{name}`` matches a non-empty run of characters, the rest literally."""
    parts = re.split(r"\{([A-Za-z_][A-Za-z0-9_]*)\}", pattern)
    rx = "".join(re.escape(p) if i % 2 == 0 else f"(?P<{p}>.+?)" for i, p in enumerate(parts))
    return re.compile(rx + r"\Z")


def load_rig(path):
    """Read and validate the rig file ``path`` into a :class:`Rig` (InputError naming file and key)."""
    path = Path(path)
    doc, text = read_toml(path)
    where = display(path)
    _refuse_unknown(doc, TOP_KEYS, where, "")
    fmt = require(doc, "format", str, where)
    if fmt not in FORMATS:
        raise InputError(where, f"expected one of {', '.join(FORMATS)} (got {fmt!r})", field="format")
    variable = require(doc, "variable", str, where, default=None)
    if fmt == "mat" and variable is None:
        raise InputError(where, "missing required field (the name of the matrix in the .mat file: samples in rows, "
                         "channels in columns)", field="variable")
    rate = quantity(doc, "sample_rate", _FREQUENCY, where, "", None, "a frequency (e.g. Hz)")
    if rate is not None and rate <= 0:
        raise InputError(where, "expected a sample rate > 0", field="sample_rate")
    time_column = require(doc, "time_column", (int, str), where, default=None)
    if rate is None and fmt == "mat":
        raise InputError(where, "missing required field (expected a frequency, e.g. { value = 10000, unit = "
                         "\"Hz\" })", field="sample_rate")
    if rate is None and fmt == "csv" and time_column is None:
        raise InputError(where, "a CSV needs sample_rate or time_column", field="sample_rate")
    pattern = require(doc, "pattern", str, where, default=None)
    if pattern is not None:
        names = re.findall(r"\{([^}]*)\}", pattern)
        bad = [n for n in names if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", n)]
        if bad or len(set(names)) != len(names):
            raise InputError(where, f"expected {{name}} fields with distinct names (got {pattern!r})", field="pattern")
    table = require(doc, "channels", dict, where)
    if not table:
        raise InputError(where, "expected at least one channel", field="channels")
    channels = tuple(_channel(name, spec, fmt, where) for name, spec in table.items())
    calibration = _calibration(doc, channels, where)
    metadata = _metadata(doc, where)
    filt = require(doc, "filter", dict, where)
    _refuse_unknown(filt, _FILTER_KEYS, where, "filter.")
    lowpass = quantity(filt, "lowpass", _FREQUENCY, where, "filter.", what="a frequency (e.g. Hz)")
    order = require(filt, "order", int, where, field_prefix="filter.", default=4)
    if not 1 <= order <= 10 or lowpass <= 0:
        raise InputError(where, "expected order 1-10 and a cut-off > 0", field="filter.order")
    notch = require(filt, "notch", (dict, list), where, field_prefix="filter.", default=[])
    notch = [notch] if isinstance(notch, dict) else notch
    notch = tuple(quantity({"notch": n}, "notch", _FREQUENCY, where, "filter.", what="a frequency (e.g. Hz)")
                  for n in notch)
    notch_q = require(filt, "notch_q", float, where, field_prefix="filter.", default=30.0)
    strokes = require(doc, "strokes", dict, where)
    _refuse_unknown(strokes, _STROKE_KEYS, where, "strokes.")
    derived = {c.name: c.dims for c in channels}
    if calibration:
        derived.update(zip(calibration.outputs, calibration.dims))
    sp = "strokes."
    position = require(strokes, "position", str, where, field_prefix=sp, default=None)
    velocity = require(strokes, "velocity", str, where, field_prefix=sp, default=None)
    if position is None and velocity is None:
        position = "position"
    normal = require(strokes, "normal", str, where, field_prefix=sp, default="normal_force")
    for key, name, dims, what in (("position", position, _LENGTH, "a length (a position channel)"),
                                  ("velocity", velocity, _VELOCITY, "a velocity"),
                                  ("normal", normal, _FORCE, "a force")):
        if name is None:
            continue
        if name not in derived:
            raise InputError(where, f"needs a channel {name!r} (expected one of {', '.join(derived)}, or set "
                             f"strokes.{key})", field=sp + key)
        if derived[name] != dims:
            raise InputError(where, f"channel {name!r} is not {what} after its gain", field=sp + key)
    fields = set(metadata) | set(re.findall(r"\{([^}]*)\}", pattern or ""))
    reject = _reject(doc, derived, fields, where)
    return Rig(str(path.resolve()), text, hashlib.sha256(text.encode()).hexdigest(), fmt, variable,
               require(doc, "group", str, where, default="trials"), rate, time_column,
               require(doc, "delimiter", str, where, default=","), pattern, metadata, channels, calibration,
               lowpass, order, notch, notch_q,
               quantity(strokes, "speed_above", _VELOCITY, where, sp, what="a velocity (e.g. mm/s)"),
               quantity(strokes, "normal_force_above", _FORCE, where, sp, what="a force (e.g. N)"),
               quantity(strokes, "trim", _TIME, where, sp, 0.0, "a time (e.g. s)"),
               quantity(strokes, "min_duration", _TIME, where, sp, 0.0, "a time (e.g. s)"),
               position, velocity, normal, reject)


def _reject(doc, derived, fields, where):
    spec = require(doc, "reject", dict, where, default=None)
    if spec is None:
        return None
    p = "reject."
    _refuse_unknown(spec, _REJECT_KEYS, where, p)
    channel = require(spec, "channel", str, where, field_prefix=p, default="normal_force")
    if channel not in derived:
        raise InputError(where, f"names no channel (expected one of {', '.join(derived)})", field=p + "channel")
    target = spec.get("target")
    if isinstance(target, str):
        if target not in fields:
            raise InputError(where, f"names metadata {target!r}, not under [metadata] or the pattern",
                             field=p + "target")
    else:
        target = quantity(spec, "target", derived[channel], where, p, what=f"the dimension of {channel!r}")
    tolerance = require(spec, "tolerance", float, where, field_prefix=p, default=0.15)
    if not 0 < tolerance < 1:
        raise InputError(where, f"expected a fraction between 0 and 1 (got {tolerance!r})", field=p + "tolerance")
    return {"channel": channel, "target": target, "tolerance": tolerance}
