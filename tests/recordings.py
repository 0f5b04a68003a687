"""A raw 1 kHz force recording with serially correlated noise, for the misfit check's tests
and its calibration study (bench/misfit.py)."""

import h5py
import numpy as np
from scipy.signal import lfilter


def power_law_recording(rng, n, phi):
    """``n`` rows at 1 kHz: time (s), normal force (N) fluctuating row to row around 1 N, and
    tangential force (N) from the empirical power law (b 0.3, c 0.67, d 0.3) plus AR(1) noise of
    lag-1 correlation ``phi`` and sd 20 mN; draws taken from ``rng`` in that order."""
    t = np.arange(n) / 1000.0
    fn = 1.0 + 0.1 * np.sin(2 * np.pi * 0.2 * t) + rng.uniform(-0.5, 0.5, n)
    innovations = rng.normal(0.0, 0.02 * np.sqrt(1 - phi**2), n)
    eps = np.empty(n)
    eps[0] = rng.normal(0.0, 0.02)
    for i in range(1, n):
        eps[i] = phi * eps[i - 1] + innovations[i]
    return t, fn, 0.3 * fn**0.67 + 0.3 * fn + eps


#: The rig file of issue 41, verbatim (tests parse it as written; docs/from-your-rig.md explains it).
ISSUE_RIG = '''schema_version = 1
format = "mat"                          # mat (v5 or v7.3) | hdf5 | csv
variable = "data"                       # the matrix: samples in rows, channels in columns
sample_rate = { value = 10000, unit = "Hz" }
pattern = "{subject}_{voltage}V_{trial}.mat"   # metadata from the file name
[metadata.voltage]
unit = "V"
[channels.tangential_force]
column = 0                              # 0-based
unit = "V"
gain = { value = 0.4444, unit = "N/V" }
bias = { first = { value = 0.5, unit = "s" } }    # mean of the first 0.5 s subtracted
[channels.normal_force]
column = 1
unit = "V"
gain = { value = 0.31, unit = "N/V" }
bias = { first = { value = 0.5, unit = "s" } }
[channels.position]
column = 2
unit = "count"
gain = { value = 0.0005, unit = "mm/count" }
[filter]
lowpass = { value = 100, unit = "Hz" }  # zero-phase Butterworth, order 4
[strokes]
speed_above = { value = 20, unit = "mm/s" }
normal_force_above = { value = 0.05, unit = "N" }
trim = { value = 0.1, unit = "s" }      # dropped at each end of a stroke
min_duration = { value = 0.3, unit = "s" }
'''


def _ar1(rng, n, phi, sd):
    """AR(1) noise of lag-1 correlation ``phi`` and stationary sd ``sd`` (n,)."""
    e = rng.normal(0.0, sd * np.sqrt(1 - phi**2), n)
    e[0] = rng.normal(0.0, sd)
    return lfilter([1.0], [1.0, -phi], e)


def stroke_recording(rng, *, rate=10_000.0, normal=0.5, lengths=(0.8, 1.2, 0.6, 1.5, 1.0, 0.9), speed=0.04,
                     law=(0.3, 0.67, 0.3), phi=0.98, noise=0.005, hum=0.02, carrier=0.05, drift=0.02, scatter=0.0):
    """A finger sliding back and forth on a force plate, in newtons and metres, at ``rate`` Hz.

    0.6 s at rest (finger off), 0.4 s loading to the stroke's normal force, then one stroke per
    entry of ``lengths`` (seconds at constant ``speed`` m/s, 50 ms speed ramps, alternating
    forward and backward, 0.3 s dwell between), unloading, 0.6 s at rest.  Each stroke's normal
    force is ``normal`` times a factor uniform in 0.95-1.05; its tangential force is the power
    law b Fn^c + d Fn (``law``) plus a stroke-to-stroke normal scatter of sd ``scatter`` N,
    its sign that of the velocity.  Both forces carry AR(1)
    noise (``phi``, sd ``noise`` N), a 50 Hz hum (``hum`` N), a 1 kHz carrier (``carrier`` N);
    the tangential channel a bias drift of ``drift`` N over the trial.  Returns (dict of (n,)
    arrays ``t, tangential_force, normal_force, position``, list of per-stroke dicts with the
    generating ``normal_force`` and ``tangential_force`` magnitudes, ``direction``, ``start``)."""
    ramp, dwell = 0.05, 0.3
    pieces_v, pieces_fn, strokes = [], [], []
    fns = normal * rng.uniform(0.95, 1.05, len(lengths))

    def seg(duration, v0, v1, f0, f1):
        m = round(duration * rate)
        pieces_v.append(np.linspace(v0, v1, m, endpoint=False))
        pieces_fn.append(np.linspace(f0, f1, m, endpoint=False))

    seg(0.6, 0, 0, 0, 0)
    seg(0.4, 0, 0, 0, fns[0])
    t_now = 1.0
    for k, (length, fn) in enumerate(zip(lengths, fns)):
        s = 1.0 if k % 2 == 0 else -1.0
        b, c, d = law
        level = b * fn**c + d * fn + (rng.normal(0.0, scatter) if scatter else 0.0)
        strokes.append({"normal_force": fn, "tangential_force": level,
                        "direction": "forward" if s > 0 else "backward", "start": t_now})
        seg(ramp, 0, s * speed, fn, fn)
        seg(length, s * speed, s * speed, fn, fn)
        seg(ramp, s * speed, 0, fn, fn)
        nxt = fns[k + 1] if k + 1 < len(fns) else fns[-1]
        seg(dwell, 0, 0, fn, nxt)
        t_now += 2 * ramp + length + dwell
    seg(0.4, 0, 0, fns[-1], 0)
    seg(0.6, 0, 0, 0, 0)
    v, fn = np.concatenate(pieces_v), np.concatenate(pieces_fn)
    n = len(v)
    t = np.arange(n) / rate
    level = np.zeros(n)
    # the friction level of the stroke each sample belongs to, scaled by |v|/speed on the ramps
    starts = [round(s["start"] * rate) for s in strokes]
    for s, a, length in zip(strokes, starts, lengths):
        m = round((2 * ramp + length) * rate)
        level[a: a + m] = s["tangential_force"]
    ft = np.sign(v) * level * np.minimum(np.abs(v) / speed, 1.0)
    x = np.cumsum(v) / rate
    hum_wave = hum * np.sin(2 * np.pi * 50 * t + 0.3)
    carrier_wave = carrier * np.sin(2 * np.pi * 1000 * t)
    ft = ft + _ar1(rng, n, phi, noise) + hum_wave + carrier_wave + drift * t / t[-1]
    fn = fn + _ar1(rng, n, phi, noise) + hum_wave + carrier_wave
    return {"t": t, "tangential_force": ft, "normal_force": fn, "position": x}, strokes


def rig_volts(signals, bias=(0.3, 0.2)):
    """The (n, 3) matrix a DAQ records for ``signals`` through the issue's rig: tangential and
    normal force in V (gains 0.4444 and 0.31 N/V, offsets ``bias`` V), position in encoder
    counts of 0.5 um."""
    return np.column_stack([signals["tangential_force"] / 0.4444 + bias[0],
                            signals["normal_force"] / 0.31 + bias[1],
                            np.round(signals["position"] * 1e3 / 0.0005)])


def write_mat_v73(path, name, matrix):
    """``matrix`` (samples x channels) as MATLAB -v7.3 writes it: an HDF5 file with a 512-byte
    user block starting ``MATLAB 7.3 MAT-file``, the matrix stored column-major (channels x samples)."""
    with h5py.File(path, "w", userblock_size=512) as fh:
        d = fh.create_dataset(name, data=np.ascontiguousarray(matrix.T))
        d.attrs["MATLAB_class"] = np.bytes_(b"double")
    with open(path, "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Sat Nov 28 12:00:00 2026 HDF5 schema 1.00 .")
