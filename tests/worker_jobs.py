"""Functions the worker-process tests run in spawned processes (tests/test_workers.py): kept in
a module of their own that imports little, since every spawned worker imports it afresh."""

import importlib
import inspect
import os
from pathlib import Path


def instance(cls):
    """An instance of exception class ``cls`` with every argument its ``__init__`` takes given a
    distinct value (so that a lost attribute shows), or one message for a class with the
    builtin ``__init__``."""
    if cls.__init__ is BaseException.__init__ or not inspect.isfunction(cls.__init__):
        return cls(f"a {cls.__name__} raised in a worker")
    kwargs, args = {}, []
    for name, p in list(inspect.signature(cls.__init__).parameters.items())[1:]:
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            continue
        value = f"{name} of a {cls.__name__}"
        if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD):
            args.append(value)
        else:
            kwargs[name] = value
    return cls(*args, **kwargs)


def raise_instance(module, qualname):
    """Raise :func:`instance` of the class named."""
    raise instance(getattr(importlib.import_module(module), qualname))


def die_on(item):
    """End the process abruptly for item "die" (as the kernel's OOM killer or a crash in
    compiled code would), else return the item doubled."""
    if item == "die":
        os._exit(9)
    return item * 2


def threads_in_worker(threads):
    """The most threads a BLAS library has inside :func:`skinfit.inference.workers.limited_threads` (which
    loads scipy's BLAS, as a fit does) and after it."""
    from skinfit.inference.workers import limited_threads, thread_count

    with limited_threads(threads):
        inside = thread_count()
    return inside, thread_count()


def zero_force(folder, rows=40):
    """The shipped electroadhesion data's first ``rows`` rows, the first with a zero normal force."""
    src = Path(__file__).resolve().parents[1] / "datasets" / "electroadhesion_synthetic"
    out = folder / "zero"
    out.mkdir()
    (out / "dataset.toml").write_text((src / "dataset.toml").read_text().replace(
        'id = "electroadhesion_synthetic"', 'id = "zero"'))
    lines = (src / "data.csv").read_text().splitlines()[:rows + 1]
    first = lines[1].split(",")
    first[2] = "0"
    lines[1] = ",".join(first)
    (out / "data.csv").write_text("\n".join(lines) + "\n")
    return out / "dataset.toml"
