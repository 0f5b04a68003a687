"""Saved results against damage, and what their checksums cost (skinfit.io.integrity).

Two studies, written to bench/results/integrity.md:

* **Zeroed windows.** 4 KiB of a saved fit.nc (and population.nc) zeroed at each offset of
  :func:`offsets` (every window touching HDF5's structures or the attributes, at four
  alignments; a sample of those inside the variables' values), the file as saved (with the
  sha256 of its bytes at its end) and without that trailer (the content checksums alone): each
  damaged copy is read as skinfit reads it (:func:`skinfit.load_fit`, then its pointwise
  groups; :func:`skinfit.analysis.population.result.load_population`) in a forked process. Each outcome is one
  of ``refused`` (an InputError of one line naming the file), ``same`` (read, every group and
  attribute identical to the undamaged file's: the window held only zeros already, or nothing
  that is read), ``CHANGED`` (read, some number or text differs: the class this guards
  against), ``crash`` (any other exception: a traceback a user would see), ``hang`` (no answer
  in 20 s: HDF5 stuck in the damaged file). ``CHANGED`` and ``crash`` must be 0.
* **Cost.** For each fit of a ``skinfit demo`` run: save time and load time (load_fit, then the
  pointwise groups) with the checksums and with them switched off (no trailer, no record,
  nothing checked), median of 3 alternating runs, and the time of the digests alone.

Usage::

    python bench/bench_integrity.py FIT.nc [POPULATION.nc] [--demo RUNS/demo] [--out bench/results/integrity.md]
"""

import argparse
import contextlib
import os
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path

import xarray as xr

import skinfit
from skinfit.errors import InputError
from skinfit.io import integrity

WINDOW = 4096


def _identical(a, b):
    try:
        xr.testing.assert_identical(a, b)
        return True
    except AssertionError:
        return False


def _read_fit(path):
    fit = skinfit.load_fit(path)
    return fit.idata


def _read_population(path):
    from skinfit.analysis.population.result import load_population

    return load_population(path).to_datatree()


def offsets(path, stride):
    """Window offsets: every one that touches HDF5's own structures or the attributes (anything
    outside the variables' values: superblock, object headers, heaps, B-trees, attribute
    storage) at four alignments (0, 1024, 2171, 3072 bytes past a 4 KiB boundary), and every
    ``stride``-th 4 KiB window inside the values at two (0 and 2171)."""
    import h5py

    size = os.path.getsize(path)
    values = []
    with h5py.File(path, "r") as f:
        def visit(_, obj):
            if isinstance(obj, h5py.Dataset) and obj.id.get_offset() is not None:
                values.append((obj.id.get_offset(), obj.id.get_offset() + obj.id.get_storage_size()))
        f.visititems(visit)

    def in_values(off):
        return any(a <= off and off + WINDOW <= b for a, b in values)

    out = set()
    for shift in (0, 1024, 2048 + 123, 3072):
        for k, off in enumerate(range(shift, size, WINDOW)):
            if not in_values(off) or (shift in (0, 2048 + 123) and k % stride == 0):
                out.add(off)
    return sorted(out), sum(b - a for a, b in values)


def _classify(damaged, read, original):
    """(outcome, message) of reading the damaged copy (see the module docstring)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tree = read(damaged)
        return ("same" if _identical(tree, original) else "CHANGED"), ""
    except InputError as exc:
        text = str(exc)
        return ("refused" if "\n" not in text and text.startswith(str(damaged)) else "crash"), text
    except Exception as exc:  # counted: a traceback a user would see
        return "crash", f"{type(exc).__name__}: {exc}"


def _child(conn, damaged, read, original):
    conn.send(_classify(damaged, read, original))
    conn.close()


def sweep(path, read, stride, unsealed=False, timeout=20.0):
    """Outcomes of zeroing WINDOW bytes at each of :func:`offsets` of ``path`` (without its
    trailer when ``unsealed``: the content checksums alone), each read in a forked process
    that is ended after ``timeout`` seconds (outcome ``hang``)."""
    import multiprocessing

    original = read(path)
    data = Path(path).read_bytes()
    if unsealed and data[-81:].startswith(integrity.TRAILER):
        data = data[:-81]
    offsets_, in_values = offsets(path, stride)
    offsets_ = [o for o in offsets_ if o < len(data)]
    outcomes, examples = {}, {}
    ctx = multiprocessing.get_context("fork")
    with tempfile.TemporaryDirectory() as tmp:
        damaged = Path(tmp) / Path(path).name
        for off in offsets_:
            copy = bytearray(data)
            copy[off:off + WINDOW] = bytes(len(copy[off:off + WINDOW]))
            damaged.write_bytes(copy)
            here, there = ctx.Pipe(duplex=False)
            proc = ctx.Process(target=_child, args=(there, damaged, read, original))
            proc.start()
            there.close()
            if here.poll(timeout):
                kind, text = here.recv()
            else:
                kind, text = "hang", f"no answer in {timeout:g} s"
            proc.kill()
            proc.join()
            outcomes[kind] = outcomes.get(kind, 0) + 1
            examples.setdefault(kind, []).append((off, text.replace(str(damaged), "FILE")[:160]))
    return len(data), in_values, len(offsets_), outcomes, examples


@contextlib.contextmanager
def _checksums_off():
    """stamp and verify replaced by no-ops (the cost baseline: the file as before the checksums)."""
    saved = integrity.stamp, integrity.take, integrity.verify, integrity.seal, integrity.check_file
    integrity.stamp = lambda tree: None
    integrity.take = lambda path, attrs, groups, **kw: None
    integrity.verify = lambda path, record, **kw: None
    integrity.seal = bytes
    integrity.check_file = lambda path: False
    try:
        yield
    finally:
        integrity.stamp, integrity.take, integrity.verify, integrity.seal, integrity.check_file = saved


def cost(fits, repeats=3):
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for path in fits:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fit = skinfit.load_fit(path)
                fit.complete()
                fit.summary()
            times = {k: [] for k in ("save_on", "save_off", "load_on", "load_off")}
            for _ in range(repeats):
                for mode in ("on", "off"):
                    with (_checksums_off() if mode == "off" else contextlib.nullcontext()):
                        target = Path(tmp) / f"{mode}.nc"
                        t0 = time.perf_counter()
                        fit.save(target)
                        times[f"save_{mode}"].append(time.perf_counter() - t0)
                        t0 = time.perf_counter()
                        with warnings.catch_warnings():
                            warnings.simplefilter("ignore")
                            skinfit.load_fit(target).complete()
                        times[f"load_{mode}"].append(time.perf_counter() - t0)
            tree = fit.idata
            t0 = time.perf_counter()
            integrity.digest_attrs(tree.attrs)
            for name in tree.children:
                integrity.digest_group(tree[name].to_dataset(inherit=False))
            digest = time.perf_counter() - t0
            rows.append({"fit": f"{fit.model_id} on {fit.dataset_id}", "MB": os.path.getsize(path) / 1e6,
                         **{k: statistics.median(v) for k, v in times.items()}, "digest": digest})
    return rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("fit")
    ap.add_argument("population", nargs="?")
    ap.add_argument("--demo", help="a skinfit demo --out folder: the cost study over its fits")
    ap.add_argument("--out", default="bench/results/integrity.md")
    ap.add_argument("--stride", type=int, default=32, help="every n-th window inside the variables' values")
    args = ap.parse_args()
    lines = ["# Saved results against damage: zeroed windows, and the cost of the checksums", "",
             f"Written by `{' '.join(['python', *sys.argv])}` (skinfit {skinfit.__version__}); see the "
             "script's docstring for what each column means.", ""]
    lines += ["## Zeroed 4 KiB windows", "", "Every window that touches HDF5's structures or the attributes, at "
              f"four alignments; every {args.stride}th inside the variables' values, at two.", "",
              "| file | bytes | windows | refused | same | CHANGED | crash | hang |",
              "|---|---|---|---|---|---|---|---|"]
    found = []
    for path, read in ((args.fit, _read_fit), (args.population, _read_population)):
        for unsealed in (False, True):
            if not path:
                continue
            t0 = time.perf_counter()
            size, in_values, n, outcomes, examples = sweep(path, read, args.stride, unsealed)
            name = Path(path).name + (" without its trailer" if unsealed else "")
            print(f"{name}: {n} windows in {time.perf_counter() - t0:.0f} s: {outcomes}", flush=True)
            lines.append(f"| {name} | {size} ({size - in_values} outside the values) | {n} | " + " | ".join(
                str(outcomes.get(k, 0)) for k in ("refused", "same", "CHANGED", "crash", "hang")) + " |")
            found.append((name, examples))
    lines += ["", "Examples of each outcome (offset: message, FILE the damaged copy):", ""]
    for name, examples in found:
        for kind, items in examples.items():
            messages = {}
            for off, text in items:
                messages.setdefault(text.split(":", 2)[-1].strip()[:90], off)
            lines.append(f"- {name}, {kind} ({len(items)}): " + "; ".join(
                f"at {off}: {m}" for m, off in list(messages.items())[:4]))
    if args.demo:
        fits = sorted(Path(args.demo).glob("**/fit.nc"))
        rows = cost(fits)
        lines += ["", f"## Cost over the {len(rows)} fits of `{args.demo}`", "",
                  "Median of 3 alternating runs, seconds; `on`: with checksums (stamped on save, checked on load and "
                  "when the pointwise groups are read), `off`: without; digest: the sha256 of every group and the "
                  "root attributes alone.", "",
                  "| fit | MB | save off | save on | load off | load on | digest |", "|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r['fit']} | {r['MB']:.1f} | {r['save_off']:.3f} | {r['save_on']:.3f} | "
                         f"{r['load_off']:.3f} | {r['load_on']:.3f} | {r['digest']:.3f} |")
        tot = {k: sum(r[k] for r in rows) for k in ("MB", "save_off", "save_on", "load_off", "load_on", "digest")}
        lines.append(f"| total | {tot['MB']:.1f} | {tot['save_off']:.2f} | {tot['save_on']:.2f} | "
                     f"{tot['load_off']:.2f} | {tot['load_on']:.2f} | {tot['digest']:.2f} |")
        lines += ["", f"Checksums add {tot['save_on'] - tot['save_off']:+.2f} s to saving and "
                      f"{tot['load_on'] - tot['load_off']:+.2f} s to loading all {len(rows)} fits "
                      f"({100 * (tot['save_on'] / tot['save_off'] - 1):+.1f}% and "
                      f"{100 * (tot['load_on'] / tot['load_off'] - 1):+.1f}%); the digests alone take "
                      f"{tot['digest']:.2f} s ({tot['MB'] / max(tot['digest'], 1e-9):.0f} MB/s)."]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
