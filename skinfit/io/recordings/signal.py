"""Calibration and zero-phase filtering of a recording, by chunks.

Each chunk of samples [start, stop) is read with ``margin`` samples more on each side, filtered
forward and backward (scipy.signal.sosfiltfilt), and cut back to [start, stop): the margin is
where the filter's slowest pole has decayed to 1e-9, so the chunks join into the signal the
whole recording filtered at once would give (to 1e-9 of its scale), while memory holds one
chunk.  Velocity is np.gradient of the filtered position on the widened chunk (central
differences at the joins too).  Every array is SI: N, m, m/s, s.
"""

import math
from dataclasses import dataclass

import numpy as np
import scipy.signal

from skinfit.errors import InputError
from skinfit.io.recordings.strokes import standard_error

__all__ = ["Filters", "Bias", "design", "check_rate", "biases", "Chunker"]

_DECAY = 1e-9


@dataclass(frozen=True)
class Filters:
    """The second-order sections at one sample rate and the margin [samples] they need."""

    rate: float
    sos: np.ndarray  # (n_sections, 6)
    margin: int
    lowpass: float | None  # [Hz] None when above this rate's Nyquist frequency (a slow channel)


def design(rig, rate):
    """Butterworth low-pass of the rig's order and the notches below Nyquist, at ``rate`` Hz.

    The base rate must exceed twice the cut-off (InputError naming filter.lowpass); a channel at
    a slower rate whose Nyquist frequency is below the cut-off is only notched where it can be."""
    nyquist = rate / 2
    sections = []
    lowpass = rig.lowpass if rig.lowpass < 0.95 * nyquist else None
    if lowpass is not None:
        sections.append(scipy.signal.butter(rig.order, lowpass, fs=rate, output="sos"))
    for f in rig.notch:
        if f < 0.95 * nyquist:
            b, a = scipy.signal.iirnotch(f, rig.notch_q, fs=rate)
            sections.append(scipy.signal.tf2sos(b, a))
    if not sections:
        return Filters(rate, np.zeros((0, 6)), 0, None)
    sos = np.vstack(sections)
    radius = float(np.max(np.abs(scipy.signal.sos2zpk(sos)[1])))
    margin = math.ceil(math.log(_DECAY) / math.log(radius)) if radius > 0 else 1
    return Filters(rate, sos, margin, lowpass)


def check_rate(rig, rate, where):
    if rig.lowpass >= 0.95 * rate / 2:
        raise InputError(where, f"low-pass {rig.lowpass:g} Hz is not below the Nyquist frequency {rate / 2:g} Hz "
                         f"of a recording at {rate:g} Hz", field="filter.lowpass")


@dataclass(frozen=True)
class Bias:
    """The bias b(t) = b0 + slope * t subtracted from a channel's raw values (raw units, t in s),
    from the mean of its first window (centre t1) and, for a drift, its last (centre t2); s1, s2
    their standard errors (raw units) from the filtered windows' scatter, autocorrelation-corrected."""

    b0: float
    slope: float
    s1: float
    s2: float | None
    t1: float
    t2: float | None

    def se(self, t):
        """Standard error of the bias at time ``t`` [s] (raw units): the two windows' errors
        weighted as the linear interpolation weighs them."""
        if self.s2 is None:
            return self.s1
        w2 = (t - self.t1) / (self.t2 - self.t1)
        return math.hypot((1 - w2) * self.s1, w2 * self.s2)


def _window(trial, c, sos, i0, i1, rig_lowpass):
    """(mean of the raw samples [i0, i1) of channel ``c``, standard error from their filtered scatter)."""
    x = trial.read(c, i0, i1)
    y = scipy.signal.sosfiltfilt(sos, x) if len(sos) and len(x) > 3 * (2 * len(sos) + 1) else x
    return float(np.mean(x)), standard_error(y, max(int(trial.rate(c) // (5 * rig_lowpass)), 1))[1]


def biases(trial, rig, filters):
    """{channel name: :class:`Bias`}: the mean of the first ``bias.first`` seconds, and with
    ``bias.last`` a drift linear in time between the two windows' centres."""
    out = {}
    for c in rig.channels:
        if c.bias_first is None:
            continue
        rate, n = trial.rate(c), trial.length(c)
        sos = filters[rate].sos

        k = min(max(round(c.bias_first * rate), 2), n)
        b1, s1 = _window(trial, c, sos, 0, k, rig.lowpass)
        t1 = (k - 1) / 2 / rate
        if c.bias_last is None:
            out[c.name] = Bias(b1, 0.0, s1, None, t1, None)
            continue
        k2 = min(max(round(c.bias_last * rate), 2), n)
        b2, s2 = _window(trial, c, sos, n - k2, n, rig.lowpass)
        t2 = (n - k2 + (n - 1)) / 2 / rate
        slope = (b2 - b1) / (t2 - t1) if t2 > t1 else 0.0
        out[c.name] = Bias(b1 - slope * t1, slope, s1, s2, t1, t2)
    return out


class Chunker:
    """Calibrated, filtered signals of one trial for base-rate samples [start, stop).

    ``signals(start, stop)`` returns {name: (stop - start,) SI array} for every derived signal
    (channels after gain, calibration-matrix outputs) plus ``velocity`` [m/s]."""

    def __init__(self, trial, rig, where):
        self.trial, self.rig, self.where = trial, rig, where
        self.rate = trial.base_rate
        check_rate(rig, self.rate, where)
        self.filters = {}
        for c in rig.channels:
            r = trial.rate(c)
            if r not in self.filters:
                self.filters[r] = design(rig, r)
        self.bias = biases(trial, rig, self.filters)
        # the widened window in base samples: the longest margin of any rate, in time
        self.margin = max(math.ceil(f.margin / r * self.rate) + 2 for r, f in self.filters.items())
        self.n = trial.n

    def _channel(self, c, a, b):
        """(times [s] or None at the base rate, SI values) of channel ``c`` over base samples
        [a, b) at its own rate (a slower channel: its samples covering that time, one more at each end)."""
        rate = self.trial.rate(c)
        if rate == self.rate:
            i0, i1 = a, b
        else:
            i0 = math.floor(a / self.rate * rate + 1e-9) - 1
            i1 = math.ceil((b - 1) / self.rate * rate - 1e-9) + 2
        i0, i1 = max(i0, 0), min(i1, self.trial.length(c))
        x = self.trial.read(c, i0, i1)
        if not np.all(np.isfinite(x)):
            bad = i0 + int(np.flatnonzero(~np.isfinite(x))[0])
            raise InputError(self.where, f"sample {bad} (0-based, at {bad / rate:.4f} s) is {float(x[bad - i0])}: "
                             "expected finite numbers (cut the recording before a gap, or fill it)",
                             field=f"channel {c.name!r}")
        if not x.flags.owndata:  # a view of a matrix read whole (v5, CSV): changed in place below
            x = x.copy()
        t = np.arange(i0, i0 + len(x)) / rate if rate != self.rate else None
        bias = self.bias.get(c.name)
        if bias is not None:
            if bias.slope:
                x -= bias.b0 + bias.slope * (np.arange(i0, i0 + len(x)) / rate if t is None else t)
            else:
                x -= bias.b0
        x *= c.factor
        return t, x

    def _filter(self, x, rate):
        f = self.filters[rate]
        if not len(f.sos) or len(x) <= 3 * (2 * len(f.sos) + 1):
            return x
        return scipy.signal.sosfiltfilt(f.sos, x)

    def signals(self, start, stop):
        a, b = max(start - self.margin, 0), min(stop + self.margin, self.n)
        grid = np.arange(a, b) / self.rate
        out, raw_in = {}, {}
        rig = self.rig
        inputs = set(rig.calibration.inputs) if rig.calibration else set()
        for c in rig.channels:
            rate = self.trial.rate(c)
            t, x = self._channel(c, a, b)
            if c.name in inputs:
                raw_in[c.name] = x
                continue
            y = self._filter(x, rate)
            if rig.position == c.name:
                v = np.gradient(y, 1.0 / rate) if len(y) > 1 else np.zeros_like(y)
                out["velocity"] = v if rate == self.rate else np.interp(grid, t, v)
            out[c.name] = y if rate == self.rate else np.interp(grid, t, y)
        if rig.calibration:
            x = np.vstack([raw_in[n] for n in rig.calibration.inputs])
            y = rig.calibration.matrix @ x
            for name, row in zip(rig.calibration.outputs, y):
                out[name] = self._filter(row, self.rate)
        if rig.velocity:
            out["velocity"] = out[rig.velocity]
        return {k: v[start - a: stop - a] for k, v in out.items()}

    def bias_se(self, t):
        """{signal: standard error [SI] of the bias subtracted from it at time ``t`` [s]}: the
        same for every stroke near ``t`` (an error shared by a trial's strokes), added in
        quadrature to each stroke's own standard error."""
        rig = self.rig
        raw = {c.name: (self.bias[c.name].se(t) * abs(c.factor) if c.name in self.bias else 0.0)
               for c in rig.channels}
        if rig.calibration:
            s = np.array([raw.pop(n) for n in rig.calibration.inputs])
            raw.update(zip(rig.calibration.outputs, np.sqrt((rig.calibration.matrix ** 2) @ s ** 2)))
        return raw

    def raw(self, start, stop):
        """Calibrated but unfiltered signals for samples [start, stop) (for the review figures)."""
        grid = np.arange(start, stop) / self.rate
        out = {}
        for c in self.rig.channels:
            t, x = self._channel(c, start, stop)
            out[c.name] = x if self.trial.rate(c) == self.rate else np.interp(grid, t, x)
        if self.rig.calibration:
            x = np.vstack([out.pop(n) for n in self.rig.calibration.inputs])
            out.update(zip(self.rig.calibration.outputs, self.rig.calibration.matrix @ x))
        return out
