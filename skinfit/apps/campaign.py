"""Campaigns: a (models x datasets x groups) matrix of fits from one TOML file and one seed.

    skinfit campaign CAMPAIGN.toml [--scheduler tcp://HOST:PORT | local] [--workers N]

The campaign file and what is checked when it is read: :mod:`skinfit.io.campaign_file`.
Everything is validated before any fit starts; mistakes raise :class:`~skinfit.errors.InputError`
naming the file and field.

Each fit's seed is :func:`skinfit.analysis.groups.derive_seed` of the campaign seed and the key
(model id, dataset id, group label), so a fit's samples depend neither on the executor, the
number of workers, the order of completion nor on which other fits the campaign holds.
Results go to ``out/<model>/<dataset>/<group>/fit.nc`` (written atomically by
:meth:`skinfit.Fit.save`) with ``summary.csv`` and ``task.json`` (the fit's specification,
written after the result).  Model and dataset ids must be plain names (letters, digits, ``.``,
``_``, ``-``; never a path) and unique within the campaign; a group's folder is a slug of its
label plus a hash of the exact label (:func:`skinfit.analysis.groups.group_dir`); every output path is
checked to stay under ``out``.  Every fit records what it was fitted to (its ``source`` attr:
the card's absolute path and the sha256 of card and data file; its ``group``), as do
``task.json`` and the index.  A fit is complete when the saved result
holds this group of these data (hash), model card and priors (hashes) and seed, and its
``task.json`` matches the current specification (options and the sampler's settings,
:func:`skinfit.inference.sampling.sampler_settings`); a saved fit that does not is reported ("stale")
and fitted again.  A restarted campaign (after a crash or a kill) skips complete fits and runs
only the others; temporary files of writers that died are removed first.  One campaign at a
time may write to an ``out`` (a second gets ``OUT: is in use by pid N``), and none into an ``out``
whose results it would drop from their index (:func:`check_campaign_out`).  ``out/index.csv`` and
``out/index.json`` list every fit (status, seconds, converged, worker, peak memory), rewritten
after each result; ``out/campaign.log`` records what each run started, skipped and finished.

Executors: local processes (``concurrent.futures.ProcessPoolExecutor``, spawn) by default;
``--scheduler local`` starts a Dask ``LocalCluster`` (one thread per worker process);
``--scheduler tcp://HOST:PORT`` submits to a running Dask scheduler, whose workers must see
the same file system (they read the cards and datasets, and write the results, themselves).
Local workers (processes and our LocalCluster's) end when the campaign's process dies, even by
SIGKILL.  Dask keys hash the whole task (:func:`task_key`), so campaigns sharing a scheduler
never share a task unless it is the same fit into the same file.  The scheduler, worker and
thread counts are checked before anything is written (a Dask scheduler needs the ``dask`` extra).

A failing fit fails alone: its error (class and one-line message) goes to the index and the log,
every other fit runs and is saved, and a rerun skips the saved ones.  Every exception a worker
raises crosses back to this process (:func:`skinfit.errors.portable`); a worker process that
dies (killed, out of memory, a crash in compiled code) breaks the pool and every fit not yet
finished: those that may have been running are run again one at a time, each in a fresh process,
the rest in a fresh pool, so only the fit that kills its worker fails
(:func:`skinfit.inference.workers.run_isolated`).

Threads: each fit runs with its BLAS and OpenMP thread pools limited to ``threads``
(``--threads``, else the file's); when neither is given, to 1, unless the worker's environment
sets one of :data:`skinfit.inference.workers.THREAD_VARIABLES` (e.g. ``OMP_NUM_THREADS``), which then
rules (:mod:`skinfit.inference.workers`).  The index's ``threads`` column: the most threads a BLAS/OpenMP
library of the worker had as the fit ended.
"""

import hashlib
import json
import os
import socket
import time
import warnings
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

try:  # Unix only (Windows has none): a worker's peak memory, else not recorded (NaN)
    import resource
except ImportError:
    resource = None

from skinfit.analysis.groups import (
    derive_seed,
    group_dir,
    group_labels,
    index_document,
    inside,
    record_source,
    source_problem,
    write_json,
)
from skinfit.errors import ConvergenceWarning, InputError, error_line, require_optional
from skinfit.inference.checkpoint import CheckpointLock, remove_stale_temps, replace_atomic
from skinfit.inference.sampling import sampler_settings
from skinfit.inference.workers import check_scheduler, collect, crossing, limited_threads, run_isolated, thread_count
from skinfit.io.arguments import check_count
from skinfit.io.campaign_file import read_campaign_file
from skinfit.io.data import load_dataset
from skinfit.results.fitting import fit

__all__ = ["Campaign", "load_campaign", "run_campaign", "run_fit"]

_INDEX_COLUMNS = ["model", "dataset", "group", "seed", "status", "seconds", "converged", "path",
                  "worker", "peak_rss_mb", "threads", "dataset_path", "dataset_sha256"]


@dataclass(frozen=True)
class Campaign:
    """A validated campaign: its fits (``tasks``, one dict each) and where they go."""

    path: str
    seed: int
    out: Path
    tasks: tuple
    scheduler: str | None
    workers: int | None
    threads: int | None = None


def load_campaign(path):
    """Read and validate a campaign file (:func:`skinfit.io.campaign_file.read_campaign_file`) into
    its fits; every model, prior and dataset is loaded once here."""
    spec = read_campaign_file(path)
    scheduler = check_scheduler(spec.scheduler, spec.path, "scheduler", need_dask=False)
    tasks, sampler, out = [], sampler_settings(), spec.out
    for entry in spec.datasets:
        dataset, ref = entry.dataset, entry.card
        levels = group_labels(dataset, spec.by)[1] if spec.by else [""]
        for m in spec.models:
            model = m.model
            for label in levels:
                rel = Path(model.id) / dataset.id / (group_dir(label) if label else "all") / "fit.nc"
                tasks.append({"model": model.id, "model_ref": m.card, "dataset": dataset.id,
                              "dataset_ref": ref, "by": list(spec.by), "group": label,
                              "seed": derive_seed(spec.seed, model.id, dataset.id, label),
                              "priors": m.priors, "split": m.split, "options": spec.options,
                              # an edited card, prior file or data file, or another sampler,
                              # makes the fit run again
                              "sha256": {"model": model.sha256, "priors": m.priors_sha256,
                                         "dataset": dataset.sha256},
                              "sampler": sampler,
                              "path": str(inside(out, out / rel))})
    return Campaign(path=spec.path, seed=spec.seed, out=out, tasks=tuple(tasks), scheduler=scheduler,
                    workers=spec.workers, threads=spec.threads)


def _spec(task):
    return json.dumps({k: v for k, v in task.items() if k != "path"}, sort_keys=True)


def run_fit(task, threads=None):
    """Run one campaign fit and write its result (top level and picklable: processes and Dask).

    The fit, its save and its summary run with the BLAS/OpenMP libraries limited to
    :func:`skinfit.inference.workers.worker_threads` threads.  An exception that would not survive the
    way back to the campaign's process is raised as a :class:`~skinfit.errors.WorkerError`
    with its class name and message."""
    return crossing(_run_fit, task, threads)


def _run_fit(task, threads):
    t0 = time.perf_counter()
    dataset = load_dataset(task["dataset_ref"])
    if dataset.sha256 != task["sha256"]["dataset"]:
        raise InputError(task["dataset_ref"], f"the data changed since the campaign was read (sha256 "
                         f"{task['sha256']['dataset'][:12]}.. -> {dataset.sha256[:12]}..): run the campaign again")
    full = dataset
    if task["by"]:
        labels, _ = group_labels(dataset, task["by"])
        dataset = dataset.subset(np.array(labels, dtype=object) == task["group"], task["group"])
    with limited_threads(threads):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)  # recorded in the index instead
            result = fit(task["model_ref"], dataset, priors=task["priors"], rng=task["seed"], split=task["split"],
                         **task["options"])
        for key in ("model", "priors"):
            if result.attrs[f"{key}_sha256"] != task["sha256"][key]:
                raise InputError(task[f"{key}_ref" if key == "model" else key], f"the {key} file changed since "
                                 "the campaign was read: run the campaign again")
        record_source(result, full, task["group"], task["by"])
        path = Path(task["path"])
        result.save(path)
        _write_text(path.parent / "summary.csv", result.summary().to_csv())
        threads_used = thread_count()  # as the fit ends: a library loaded during it is counted too
    record = {"status": "done", "seconds": round(time.perf_counter() - t0, 3), "converged": result.converged,
              "worker": f"{socket.gethostname()}:{os.getpid()}", "peak_rss_mb": _peak_rss_mb(),
              "threads": threads_used}
    write_json(path.parent / "task.json", {"spec": json.loads(_spec(task)), **record})
    return record


def _peak_rss_mb():
    """This process's peak resident memory in MiB (Linux reports KiB), NaN where unknown."""
    if resource is None:
        return float("nan")
    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)


def _completed(task):
    """``(record, problem)``: the saved record of a complete fit with this specification (else
    None), and why a fit found in the task's folder is not reused (else None)."""
    path = Path(task["path"])
    record_path = path.parent / "task.json"
    if not path.exists():
        return None, None
    try:
        tree = xr.open_datatree(path)
        attrs = dict(tree.attrs)
        tree.close()
    except (OSError, ValueError) as exc:
        return None, f"unreadable fit.nc ({type(exc).__name__})"
    # the result itself must say it is this fit: data, cards, group and seed
    problem = source_problem(attrs, task["group"], task["sha256"]["dataset"])
    for key in ("model", "priors"):
        if problem is None and attrs.get(f"{key}_sha256") != task["sha256"][key]:
            problem = f"fitted with another {key} file (sha256 {str(attrs.get(f'{key}_sha256'))[:12]}..)"
    if problem is None and attrs.get("seed") != task["seed"]:
        problem = f"fitted with seed {attrs.get('seed')}, not {task['seed']}"
    if problem is not None:
        return None, problem
    try:
        record = json.loads(record_path.read_text())
    except (OSError, ValueError):
        return None, None  # killed between the result and its record: run again
    if json.dumps(record.get("spec"), sort_keys=True) != _spec(task):
        return None, "its task.json records other options or sampler settings"
    return record, None


def run_campaign(campaign, *, scheduler=None, workers=None, threads=None, echo=print):
    """Run every fit of a campaign not yet complete; returns the index table.

    Parameters
    ----------
    campaign : Campaign or path of a campaign file
    scheduler : None, "local" or "tcp://HOST:PORT"
        Overrides the file's ``scheduler``; None (and none in the file) uses local processes.
    workers : int, optional
        Local worker processes (or LocalCluster workers); default the file's, else the CPU count.
    threads : int, optional
        BLAS/OpenMP threads of each fit; default the file's, else
        :func:`skinfit.inference.workers.worker_threads` (1 unless the environment sets OMP_NUM_THREADS or
        the like).

    Every argument is checked (InputError, or MissingDependency for a Dask scheduler without
    the ``dask`` extra) before anything is written.
    """
    scheduler = check_scheduler(scheduler)
    workers = check_count(workers, "--workers", None, optional=True)
    threads = check_count(threads, "--threads", None, optional=True)
    campaign = campaign if isinstance(campaign, Campaign) else load_campaign(campaign)
    scheduler = check_scheduler(scheduler or campaign.scheduler, campaign.path, "scheduler")
    workers = workers or campaign.workers or os.cpu_count() or 1
    threads = threads or campaign.threads
    out = campaign.out
    out.mkdir(parents=True, exist_ok=True)
    with CheckpointLock(out / "campaign"):  # one campaign at a time per out (else "OUT is in use by pid N")
        return _run_locked(campaign, scheduler, workers, threads, echo)


def check_campaign_out(campaign):
    """Refuse, before anything is run or written, a campaign's ``out`` folder whose results
    this campaign would drop from their index: a single fit (``fit.nc``) or a run by groups
    of ``skinfit fit`` (whose ``index.json`` the campaign's would replace), an ``index.json``
    skinfit cannot read, or another campaign's index listing fits whose files are there but
    which this campaign does not list (they would be left on disk, no longer indexed). The
    same campaign, edited or extended, may run in its folder again."""
    out = campaign.out
    if (out / "fit.nc").exists():
        raise InputError(out, "holds a single fit (fit.nc): give the campaign another out (nothing was written)")
    index = out / "index.json"
    if not index.exists():
        if (out / "index.csv").exists():  # it would be replaced, and no campaign wrote it (none without its json)
            raise InputError(out, "holds an index.csv that no campaign wrote (no index.json beside it): give the "
                                  "campaign another out (nothing was written)")
        return
    try:
        kind, rows = index_document(index)
        listed = [str(row["path"]) for row in rows] if kind == "campaign" else None
    except (InputError, KeyError, TypeError):
        raise InputError(index, "not a campaign's index skinfit can read: give the campaign another out, or remove "
                                "it to run here (nothing was written)") from None
    if listed is None:
        raise InputError(out, f"holds a run by groups of {rows.get('model', '?')} (index.json of skinfit fit --by): "
                              "give the campaign another out (nothing was written)")
    root = out.resolve()
    mine = {Path(task["path"]).resolve() for task in campaign.tasks}
    dropped = [p for p in listed if (target := (out / p).resolve()) not in mine and target.is_relative_to(root)
               and target.is_file()]
    if dropped:
        raise InputError(out, f"holds {len(dropped)} fit(s) of another campaign that {Path(campaign.path).name} "
                              f"does not list (e.g. {dropped[0]}): they would drop out of the index; give the "
                              "campaign another out, or list them in it, or remove them (nothing was written)")


def _run_locked(campaign, scheduler, workers, threads, echo):
    out = campaign.out
    check_campaign_out(campaign)
    stale = remove_stale_temps(out)
    with open(out / "campaign.log", "a", buffering=1) as log:
        for p in stale:
            log.write(f"{_now()} removed {os.path.relpath(p, out)} (left by a killed writer)\n")
        executor = scheduler or f"processes x {workers}"
        log.write(f"{_now()} start {campaign.path} ({len(campaign.tasks)} fits, executor {executor})\n")
        rows, todo = [], []
        for i, task in enumerate(campaign.tasks):
            row = {"model": task["model"], "dataset": task["dataset"], "group": task["group"], "seed": task["seed"],
                   "status": "pending", "seconds": np.nan, "converged": None,
                   "path": os.path.relpath(task["path"], out), "worker": "", "peak_rss_mb": np.nan, "threads": None,
                   "dataset_path": task["dataset_ref"], "dataset_sha256": task["sha256"]["dataset"]}
            done, problem = _completed(task)
            if problem is not None:
                echo(f"  stale    {_key(task)}: the saved fit is not reused: {problem}")
                log.write(f"{_now()} stale {_key(task)}: {problem}\n")
            if done is not None:
                row.update({k: done.get(k) for k in ("seconds", "converged", "worker", "peak_rss_mb", "threads")},
                           status="complete")
                log.write(f"{_now()} skip {_key(task)} (complete)\n")
            else:
                todo.append(i)
            rows.append(row)
        _write_index(out, rows)
        echo(f"campaign {campaign.path}: {len(campaign.tasks)} fits, {len(campaign.tasks) - len(todo)} already "
             f"complete, {len(todo)} to run ({executor})")

        def finish(i, record=None, error=None):
            task = campaign.tasks[i]
            if error is None:
                rows[i].update(record)
                log.write(f"{_now()} done {_key(task)} {record['seconds']:.2f} s converged={record['converged']}\n")
            else:
                rows[i].update(status=f"failed: {error_line(error)}")
                log.write(f"{_now()} failed {_key(task)}: {error_line(error)}\n")
            _write_index(out, rows)
            echo(f"  {rows[i]['status']:8s} {_key(task)}" + (f"  {rows[i]['seconds']:.1f} s, converged="
                                                            f"{rows[i]['converged']}" if error is None else ""))

        try:
            for i in todo:
                log.write(f"{_now()} run {_key(campaign.tasks[i])}\n")
            if todo and scheduler is None:
                run_isolated(partial(run_fit, threads=threads), {i: campaign.tasks[i] for i in todo}, workers, finish)
            elif todo:
                _run_dask(campaign, todo, scheduler, workers, threads, finish)
        finally:
            log.write(f"{_now()} end\n")
    return pd.DataFrame(rows, columns=_INDEX_COLUMNS)


def _run_dask(campaign, todo, scheduler, workers, threads, finish):
    # the optional dask extra, imported only for a Dask executor (checked before the run: check_scheduler)
    distributed = require_optional("distributed", "dask")
    Client, LocalCluster, dask_completed = distributed.Client, distributed.LocalCluster, distributed.as_completed

    cluster = None
    if scheduler == "local":
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)  # its worker processes end with ours, even on a SIGKILL (Dask's own watch)
    else:
        try:
            client = Client(scheduler, timeout=30)
        except Exception as exc:  # unreachable (OSError, TimeoutError), or a transport distributed lacks
            raise InputError("--scheduler", f"cannot reach the Dask scheduler at {scheduler} "
                                            f"({error_line(exc)})") from None
    try:
        futures = {client.submit(run_fit, campaign.tasks[i], threads, key=task_key(campaign.tasks[i]), pure=False): i
                   for i in todo}
        for fut in dask_completed(list(futures)):
            collect(fut, futures[fut], finish)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def task_key(task):
    """The Dask key of a fit: a hash of its whole specification and output path, so two
    campaigns on one scheduler share a key only when they are the same fit into the same file."""
    digest = hashlib.sha256((_spec(task) + "\0" + task["path"]).encode()).hexdigest()[:32]
    return f"skinfit-fit-{task['seed']}-{digest}"


def _write_text(path, text):
    replace_atomic(path, text.encode())


def _write_index(out, rows):
    table = pd.DataFrame(rows, columns=_INDEX_COLUMNS)
    write_json(out / "index.json", rows)
    _write_text(out / "index.csv", table.to_csv(index=False))


def _key(task):
    return f"{task['model']} / {task['dataset']}" + (f" / {task['group']}" if task["group"] else "")


def _now():
    return time.strftime("%Y-%m-%dT%H:%M:%S")
