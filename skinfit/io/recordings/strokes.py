"""Strokes: where the finger slides, and each stroke reduced to means with standard errors.

A stroke is a run of samples where |v| exceeds ``speed_above`` and the normal force exceeds
``normal_force_above``, with one sign of v (forward v > 0, backward v < 0).  ``trim`` seconds
are dropped at each end (the speed and force ramps) and a kept window shorter than
``min_duration`` is dropped, with that reason.  Each kept window gives, per signal, the mean and
its standard error sd / sqrt(n_eff), n_eff = n / tau with tau the integrated autocorrelation
time (emcee.autocorr.integrated_time, Sokal's automatic window c = 5): the scatter of a
filtered, serially correlated signal counts as n_eff independent samples, not n (less the
bias of the windowed estimate, see :func:`standard_error`).  tau is
measured on the window subsampled to five times the low-pass cut-off (the filtered signal holds
nothing above the cut-off; 20 times fewer samples at 10 kHz and 100 Hz).
"""

import math

import numpy as np
from emcee.autocorr import integrated_time

__all__ = ["runs", "window", "reduce_window", "standard_error"]

_C = 5  # Sokal's automatic window: the smallest M >= _C * tau(M)


def runs(code):
    """(start, stop, sign) of each run of equal non-zero values of the int8 array ``code``
    (+1 forward, -1 backward, 0 neither); stop exclusive."""
    code = np.asarray(code, dtype=np.int8)
    if not len(code):
        return []
    edges = np.flatnonzero(np.diff(code)) + 1
    starts = np.concatenate([[0], edges])
    stops = np.concatenate([edges, [len(code)]])
    return [(int(a), int(b), int(code[a])) for a, b in zip(starts, stops) if code[a] != 0]


def window(start, stop, rate, trim, min_duration):
    """The kept window (a, b) of a stroke [start, stop) at ``rate`` Hz after trimming ``trim`` s
    at each end, and the reason it is dropped ("" when kept)."""
    k = round(trim * rate)
    a, b = start + k, stop - k
    if (b - a) / rate < min_duration or b - a < 2:
        return a, b, f"kept window {max(b - a, 0) / rate:.3g} s after trimming {trim:g} s at each end is shorter " \
                     f"than min_duration {min_duration:g} s"
    return a, b, ""


def standard_error(x, step=1):
    """(mean, se, n_eff) of a serially correlated series ``x`` (n,): se = sd / sqrt(n_eff),
    n_eff = n / tau.  ``step``: tau is measured on every ``step``-th sample (in those samples'
    units), for a signal low-pass filtered well below its sample rate: its autocorrelation is
    then the same sampled more coarsely, and the FFT ``step`` times shorter."""
    x = np.asarray(x, dtype=float)
    sd = float(np.std(x, ddof=1)) if len(x) > 1 else 0.0
    sub = x[::step]
    n = len(sub)
    tau = float(integrated_time(sub, c=_C, tol=0, quiet=True)[0]) if sd > 0 and n > 1 else 1.0
    tau = max(tau, 1.0)
    # The window's own mean is subtracted before the autocovariances are summed over |k| <= M
    # (M ~ c tau): each is low by var(mean) = sigma^2 tau / n, so sd^2 tau_hat / n is low by the
    # factor 1 - (2M + 1) / n; n_eff is divided by it (to at least one sample).
    n_eff = max(n / tau * (1.0 - min((2 * math.ceil(_C * tau) + 1) / n, 0.9)), 1.0)
    return float(np.mean(x)), sd / np.sqrt(n_eff), n_eff


def reduce_window(signals, names, rectify, step=1):
    """One stroke's row: for each signal of ``names`` its mean and ``<name>_se``, the mean speed
    |v| and ``speed_se``, and ``n_eff`` (the smallest over the signals: the most correlated);
    a signal in ``rectify`` is reported as |mean| (a force whose sign follows the stroke);
    ``step`` as for :func:`standard_error`."""
    row, n_effs = {}, []
    for name in names:
        mean, se, n_eff = standard_error(signals[name], step)
        row[name] = abs(mean) if name in rectify else mean
        row[f"{name}_se"] = se
        n_effs.append(n_eff)
    mean, se, n_eff = standard_error(np.abs(signals["velocity"]), step)
    row["speed"], row["speed_se"] = mean, se
    n_effs.append(n_eff)
    row["n_eff"] = float(min(n_effs))
    return row
