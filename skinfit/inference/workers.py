"""Worker processes of a campaign: the executor a user names, the BLAS/OpenMP threads of each fit
and a pool in which a fit that kills its worker fails alone.

Threads: a fit in a worker runs with its BLAS and OpenMP thread pools limited (threadpoolctl) to
the ``threads`` the user gives (``skinfit campaign --threads``, a campaign file's ``threads``);
when none is given, to 1, unless the worker's environment sets one of :data:`THREAD_VARIABLES`
(e.g. ``OMP_NUM_THREADS``), which then rules.  One worker per core with one thread each: a fit's
arrays are small (walkers x rows), and N workers each running N BLAS threads on N cores
oversubscribe them (16 workers on 16 cores ran each fit 54% slower than one worker, as reported
in issue 39; 2 workers on 2 cores: bench/results/campaign.md).
"""

import multiprocessing
import os
import threading
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from urllib.parse import urlsplit

from threadpoolctl import threadpool_info, threadpool_limits

from skinfit.errors import InputError, WorkerError, portable, require_optional
from skinfit.inference.checkpoint import watch_parent

__all__ = ["THREAD_VARIABLES", "SCHEMES", "check_scheduler", "worker_threads", "limited_threads",
           "thread_count", "run_isolated", "collect", "crossing", "forkable"]

#: Environment variables by which a user sets the threads of BLAS/OpenMP libraries; any of them
#: set in a worker's environment (and no ``threads`` given) leaves its libraries as they are.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")
#: Dask's address schemes a campaign can submit to (``SCHEME://HOST:PORT``).
SCHEMES = ("tcp", "tls", "ucx", "ws", "wss")


def check_scheduler(value, where="--scheduler", field=None, *, need_dask=True):
    """``value`` if it names an executor a campaign can use: None (local processes), ``"local"``
    (a Dask LocalCluster) or a Dask scheduler's address ``SCHEME://HOST:PORT`` (:data:`SCHEMES`);
    else an InputError naming ``where``.  With ``need_dask``, a Dask executor without
    distributed installed raises :class:`~skinfit.errors.MissingDependency` naming the ``dask``
    extra (a run checks it; reading a campaign file does not)."""
    if value is None:
        return None
    expected = (f"expected 'local' or a Dask scheduler's address like tcp://HOST:PORT (schemes: "
                f"{', '.join(SCHEMES)}; got {value!r})")
    if not isinstance(value, str) or not value.isprintable() or any(c.isspace() for c in value):
        raise InputError(where, expected, field=field)  # (urlsplit would drop a tab or newline unseen)
    if value != "local":
        try:
            parts = urlsplit(value)
            port = parts.port  # ValueError: not a number in 0..65535
        except ValueError:
            raise InputError(where, expected, field=field) from None
        if parts.scheme not in SCHEMES or not parts.hostname or not port or parts.path not in ("", "/") \
                or parts.query or parts.fragment or parts.username is not None:
            raise InputError(where, expected, field=field)
    if need_dask:
        require_optional("distributed", "dask")
    return value


def worker_threads(threads=None):
    """The BLAS/OpenMP thread limit of a fit in a worker: ``threads`` when given, else None (no
    limit: the user's setting rules) when the environment sets one of :data:`THREAD_VARIABLES`,
    else 1."""
    if threads is not None:
        return threads
    return None if any(os.environ.get(v, "").strip() for v in THREAD_VARIABLES) else 1


@contextmanager
def limited_threads(threads=None):
    """BLAS and OpenMP libraries limited to :func:`worker_threads` threads while in the block
    (threadpoolctl; None: left as they are).  scipy's BLAS, which a fit loads, is loaded first:
    threadpoolctl limits only the libraries loaded when the limit is set."""
    import scipy.linalg  # noqa: F401  (function level: loaded here for the limit, not at import)

    with threadpool_limits(limits=worker_threads(threads)):
        yield


def thread_count():
    """The most threads any BLAS/OpenMP library of this process has now (None: none loaded)."""
    return max((lib["num_threads"] for lib in threadpool_info()), default=None)


def forkable():
    """True when this process may fork workers: POSIX fork exists and no other thread runs here.

    A process that forks while other threads run (a notebook kernel's, a Dask client's, a
    caller's) hands its child every lock those threads held, held forever: the child may
    deadlock, and Python warns (DeprecationWarning "This process is multi-threaded, use of
    fork() may lead to deadlocks in the child").  The report's figure workers and SBC's
    simulation workers are forked only from a process without other threads (else their work
    runs in the calling process)."""
    return "fork" in multiprocessing.get_all_start_methods() and threading.active_count() == 1


def crossing(target, *args):
    """``target(*args)`` in a worker: an exception that would not survive the way back to the
    parent process is raised as a :class:`~skinfit.errors.WorkerError` (class name, message)."""
    try:
        return target(*args)
    except Exception as exc:
        back = portable(exc)
        if back is exc:
            raise
        raise back from None


def run_isolated(target, items, workers, finish):
    """``target(item)`` for each of ``items`` (a dict key -> item) in ``workers`` spawned
    processes, which end when this one dies; as each ends, ``finish(key, result)`` or
    ``finish(key, error=exception)`` (:func:`collect`).

    A worker that dies (killed, out of memory, a crash in compiled code) breaks the pool and
    fails every item not yet finished with BrokenProcessPool.  The pool hands items out in
    submission order, at most ``2 workers + 1`` at a time (running and queued), so only the
    first ``2 workers + 1`` of those can have been running: each runs again alone, in a fresh
    process (one that kills its worker then fails), and the rest again in a fresh pool."""
    def pool(n):
        return ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=watch_parent, initargs=(os.getpid(),))

    keys = list(items)
    while keys:
        broken = set()
        with pool(min(workers, len(keys))) as executor:
            futures = {executor.submit(target, items[key]): key for key in keys}
            for fut in as_completed(futures):
                if isinstance(fut.exception(), BrokenProcessPool):
                    broken.add(futures[fut])
                else:
                    collect(fut, futures[fut], finish)
        keys = [key for key in keys if key in broken]  # submission order
        suspects, keys = keys[:2 * workers + 1], keys[2 * workers + 1:]
        for key in suspects:
            with pool(1) as executor:
                collect(executor.submit(target, items[key]), key, finish)


def collect(future, key, finish):
    """``finish(key, result)`` for a future that succeeded, else ``finish(key, error=exc)`` (one
    whose worker died: a :class:`~skinfit.errors.WorkerError` of kind BrokenProcessPool)."""
    try:
        result = future.result()
    except BrokenProcessPool:
        return finish(key, error=WorkerError("BrokenProcessPool", "its worker process died (killed, out of memory "
                                                                  "or a crash in compiled code)"))
    except Exception as exc:  # recorded by finish; the other items go on
        return finish(key, error=exc)
    return finish(key, result)
