"""Checkpoints of a running fit: the chain so far and everything needed to continue it exactly.

A checkpoint is data, never a pickle.  One HDF5 file (``skinfit fit --out RUN`` uses
``RUN/checkpoint.h5``) holds

* group ``chain``, in emcee's ``HDFBackend`` layout: datasets ``chain`` (n, nwalkers, d) in
  sampling coordinates, ``log_prob`` (n, nwalkers), ``accepted`` (nwalkers,); attributes
  ``iteration`` (= n), ``nwalkers``, ``ndim`` and ``random_state_0..4``, the state of emcee's
  ``RandomState`` after step n.  ``emcee.backends.HDFBackend(path, name="chain",
  read_only=True)`` reads it;
* group ``skinfit``: what the chain belongs to (``meta``: ordered parameter names, sha256 of
  the model card, prior file and dataset, noise/split/constants, seed, number of walkers,
  sampler and optimiser settings), the MAP, the first independence proposal (JSON) and the
  initial walkers ``p0``, the caller's numpy
  Generator state (``bit_generator.state`` as JSON) when sampling began, the posterior's
  evaluation counters and the sampling time so far.

Every write replaces the whole file atomically (temporary file, fsync, rename, fsync of the
directory), so a kill -9 or a power loss leaves the previous checkpoint or the new one, never
a torn file.  :func:`skinfit.inference.sampling.run_emcee` writes after the first step at which
``interval`` seconds (default 30) have passed since the last write -- lengthened to 50x the
last write's duration, so writing costs at most ~2% of the wall time -- and at the end of
sampling or on KeyboardInterrupt.  (emcee's ``HDFBackend`` writes at every step instead.)

A resumed fit (:func:`load_checkpoint` + :meth:`Saved.verify`) reuses the MAP, the walkers and
the random states of the checkpoint, so its final chain equals that of an uninterrupted run
with the same seed.  Resuming against a changed model card, prior file, dataset, parameter
order or sampling setup is refused with an :class:`~skinfit.errors.InputError`.
"""

import io
import json
import os
import re
import socket
import tempfile
import threading
import time
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import h5py
import numpy as np

from skinfit.errors import InputError

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: CheckpointLock is a no-op
    fcntl = None

__all__ = ["FORMAT", "run_identity", "Checkpoint", "Saved", "load_checkpoint", "CheckpointLock",
           "temp_file", "remove_stale_temps", "replace_atomic"]

#: Version of the checkpoint layout and of the sampler that wrote it; a checkpoint of another
#: version is refused (2: adaptive independence proposal, whose chain a format-1 run cannot continue).
FORMAT = 2


def run_identity(post, *, seed, nwalkers, settings):
    """What a chain belongs to: compared field by field before a resume.

    ``post`` is the :class:`~skinfit.posterior.Posterior`; ``seed`` the integer seed (None
    when the caller gave a Generator or no seed); ``settings`` the sampler and optimiser
    settings (a JSON-able dict).
    """
    priors = post.priors
    return {
        "format": FORMAT,
        "parameters": list(post.names),
        "model_id": post.model.id, "model_sha256": post.model.sha256,
        "priors_id": priors.id, "priors_sha256": priors.sha256,
        "priors": {name: priors[name].describe() for name in priors},
        "dataset_id": post.dataset.id, "dataset_sha256": post.dataset.sha256,
        "setup": {"noise": dict(post.noise), "split": {p: list(c) for p, c in post.split.items()},
                  "constants": {k: float(v) for k, v in post.constants.items()}},
        "nwalkers": int(nwalkers),
        "seed": None if seed is None else int(seed),
        "settings": json.loads(json.dumps(settings)),
    }


def _short(digest):
    return (digest or "none")[:12]


def _differences(saved, now):
    """Human-readable reasons why a checkpoint does not belong to the current run."""
    out = []
    if saved.get("format") != now["format"]:
        return [f"checkpoint format {saved.get('format')!r} is not this skinfit's format {now['format']}"]
    if saved["parameters"] != now["parameters"]:
        if sorted(saved["parameters"]) == sorted(now["parameters"]):
            out.append(f"parameter order differs: checkpoint has {saved['parameters']}, now {now['parameters']}")
        else:
            out.append(f"parameters differ: checkpoint has {saved['parameters']}, now {now['parameters']}")
    for key, label in (("model", "model card"), ("priors", "prior file"), ("dataset", "dataset")):
        a, b = saved[f"{key}_sha256"], now[f"{key}_sha256"]
        if a != b or saved[f"{key}_id"] != now[f"{key}_id"]:
            out.append(f"{label} changed ({saved[f'{key}_id']} sha256 {_short(a)}.. -> "
                       f"{now[f'{key}_id']} sha256 {_short(b)}..)")
    if saved["priors"] != now["priors"]:
        changed = sorted(k for k in set(saved["priors"]) | set(now["priors"])
                         if saved["priors"].get(k) != now["priors"].get(k))
        out.append(f"priors changed for {', '.join(changed)}")
    for key in ("noise", "split", "constants"):
        if saved["setup"][key] != now["setup"][key]:
            out.append(f"{key} differs: checkpoint {saved['setup'][key]}, now {now['setup'][key]}")
    if saved["nwalkers"] != now["nwalkers"]:
        out.append(f"number of walkers differs: checkpoint {saved['nwalkers']}, now {now['nwalkers']}")
    if now["seed"] is not None and saved["seed"] != now["seed"]:
        out.append(f"seed differs: checkpoint {saved['seed']}, now {now['seed']}")
    for key in sorted(set(saved["settings"]) | set(now["settings"])):
        if saved["settings"].get(key) != now["settings"].get(key):
            out.append(f"setting {key} differs: checkpoint {saved['settings'].get(key)!r}, "
                       f"now {now['settings'].get(key)!r}")
    return out


# ---- JSON for numpy Generator states (PCG64 holds 128-bit ints; MT19937 holds arrays) ----------
def _to_json(obj):
    if isinstance(obj, dict):
        return {k: _to_json(v) for k, v in obj.items()}
    if isinstance(obj, np.ndarray):
        return {"__ndarray__": obj.tolist(), "dtype": str(obj.dtype)}
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def _from_json(obj):
    if isinstance(obj, dict):
        if "__ndarray__" in obj:
            return np.asarray(obj["__ndarray__"], dtype=obj["dtype"])
        return {k: _from_json(v) for k, v in obj.items()}
    return obj


@dataclass(frozen=True)
class Saved:
    """A checkpoint read back from disk (see :func:`load_checkpoint`)."""

    path: str
    meta: dict
    iteration: int
    chain: np.ndarray  # (iteration, nwalkers, d), sampling coordinates
    log_prob: np.ndarray  # (iteration, nwalkers)
    accepted: np.ndarray  # (nwalkers,) accepted proposals per walker so far
    random_state: tuple  # emcee's RandomState after step `iteration`
    p0: np.ndarray  # (nwalkers, d) the initial walkers
    generator_state: dict  # the caller's numpy Generator when sampling began
    map: dict  # theta, log_density, starts, evaluations, seconds
    proposal: dict  # the first independence proposal (MixtureT.to_dict)
    importance: list  # the importance rounds that made it
    counts: dict  # Posterior.counts at the time of the write
    seconds: float  # sampling wall time so far

    def verify(self, identity):
        """Raise an InputError naming every difference between the checkpoint and ``identity``."""
        diffs = _differences(self.meta, identity)
        if diffs:
            raise InputError(self.path, "cannot resume: " + "; ".join(diffs) + ". Resume with the same "
                             "model card, priors, dataset and options, or delete the checkpoint to start afresh")


def load_checkpoint(path):
    """Read a checkpoint written by :class:`Checkpoint`; InputError if it is not one."""
    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            g, s = f["chain"], f["skinfit"]
            n = int(g.attrs["iteration"])
            rs = tuple(g.attrs[f"random_state_{i}"] for i in range(5))
            rs = (str(rs[0]), np.asarray(rs[1], dtype=np.uint32), int(rs[2]), int(rs[3]), float(rs[4]))
            return Saved(
                path=str(path), meta=json.loads(s.attrs["meta"]), iteration=n,
                chain=g["chain"][:n], log_prob=g["log_prob"][:n], accepted=g["accepted"][...],
                random_state=rs, p0=s["p0"][...],
                generator_state=_from_json(json.loads(s.attrs["generator_state"])),
                map=json.loads(s.attrs["map"]), proposal=json.loads(s.attrs["proposal"]),
                importance=json.loads(s.attrs["importance"]), counts=json.loads(s.attrs["counts"]),
                seconds=float(s.attrs["seconds"]))
    except FileNotFoundError:
        raise InputError(path, "no such checkpoint") from None
    except (OSError, KeyError, ValueError, TypeError, IndexError) as exc:
        raise InputError(path, f"not a readable skinfit checkpoint ({type(exc).__name__}: {exc}); "
                         f"delete it to start afresh") from None


class Checkpoint:
    """Writes the checkpoint file of one run, atomically, when asked or when due.

    Parameters
    ----------
    path : path-like
        The checkpoint file (HDF5).
    identity : dict
        :func:`run_identity` of the run.
    interval : float
        Seconds between periodic writes; lengthened to 50x the last write's duration.
    """

    def __init__(self, path, identity, *, interval=30.0):
        self.path = Path(path)
        self.identity = identity
        self.map_record = None
        self.interval = float(interval)
        self.p0 = None
        self.generator_state = None
        self.last_write = time.monotonic()
        self.write_seconds = 0.0  # total time spent writing
        self.writes = 0
        self._last_duration = 0.0

    def start(self, p0, generator_state, map_result, proposal, importance=()):
        """Record the initial walkers, the Generator state when sampling begins, the MAP, the
        first independence proposal (a :class:`~skinfit.inference.proposal.MixtureT`) and the record of
        the importance rounds that made it."""
        self.p0 = np.array(p0, dtype=float)
        self.generator_state = generator_state
        self.map_record = map_result.as_record()
        self.proposal = proposal.to_dict()
        self.importance = list(importance)

    def due(self):
        """True when the (lengthened) interval has passed since the last write."""
        return time.monotonic() - self.last_write >= max(self.interval, 50.0 * self._last_duration)

    def write(self, *, chain, log_prob, accepted, random_state, counts, seconds):
        """Replace the checkpoint file with the state after ``len(chain)`` steps."""
        t0 = time.monotonic()
        n, nwalkers, ndim = chain.shape if len(chain) else (0, *self.p0.shape)

        def build(f):
            g = f.create_group("chain")
            g.attrs["version"] = metadata.version("emcee")  # as emcee's HDFBackend records it
            g.attrs["nwalkers"] = nwalkers
            g.attrs["ndim"] = ndim
            g.attrs["has_blobs"] = False
            g.attrs["iteration"] = n
            g.create_dataset("accepted", data=np.asarray(accepted, dtype=float))
            g.create_dataset("chain", data=np.asarray(chain, dtype=float).reshape(n, nwalkers, ndim),
                             maxshape=(None, nwalkers, ndim), chunks=True)
            g.create_dataset("log_prob", data=np.asarray(log_prob, dtype=float).reshape(n, nwalkers),
                             maxshape=(None, nwalkers), chunks=True)
            for i, v in enumerate(random_state):
                g.attrs[f"random_state_{i}"] = v
            s = f.create_group("skinfit")
            s.attrs["meta"] = json.dumps(self.identity)
            s.attrs["map"] = json.dumps(self.map_record)
            s.attrs["proposal"] = json.dumps(self.proposal)
            s.attrs["importance"] = json.dumps(self.importance)
            s.attrs["generator_state"] = json.dumps(_to_json(self.generator_state))
            s.attrs["counts"] = json.dumps({k: int(v) for k, v in counts.items()})
            s.attrs["seconds"] = float(seconds)
            s.attrs["written_unix"] = time.time()
            s.create_dataset("p0", data=self.p0)

        write_atomic(self.path, build)
        self._last_duration = time.monotonic() - t0
        self.write_seconds += self._last_duration
        self.writes += 1
        self.last_write = time.monotonic()


def user_file_mode():
    """The mode a plain ``open(path, "w")`` would give a new file: 0o666 less the umask
    (``tempfile.mkstemp`` creates 0o600 files; :func:`temp_file` gives its files this mode)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def write_atomic(path, build):
    """Create ``path`` as an HDF5 file filled by ``build(h5py.File)``: all or nothing.

    Written to a temporary file in the same directory, flushed to disk, renamed over
    ``path`` (atomic on POSIX), then the directory entry flushed.  An interruption at any
    point leaves the previous file (or none) at ``path``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    image = io.BytesIO()  # HDF5 builds in memory: on a full disk its own writes crashed the process (rc 139)
    with h5py.File(image, "w") as f:
        build(f)
    replace_atomic(path, image.getbuffer())


def replace_atomic(path, data):
    """Put the bytes ``data`` at ``path``, all or nothing: written to a :func:`temp_file` beside
    it, flushed to disk, renamed over ``path`` (atomic on POSIX), the directory entry flushed.
    A full or read-only disk is an OSError naming ``path``, the previous file (or none) kept."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temp_file(path)
    try:
        try:
            with os.fdopen(os.open(tmp, os.O_WRONLY | os.O_TRUNC), "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
        except OSError as exc:
            raise OSError(exc.errno, f"cannot write: {exc.strerror}", str(path)) from None
        os.replace(tmp, path)
        _fsync_dir(path.parent)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _fsync_dir(directory):
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # e.g. platforms without directory file descriptors
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _host():
    return re.sub(r"[^A-Za-z0-9-]", "-", socket.gethostname())[:40] or "host"


#: Temporary files of an atomic write: ``.<name>.<host>.<pid>-<random>.tmp`` beside the target.
_TEMP = re.compile(r"^\.(?P<name>.+)\.(?P<host>[A-Za-z0-9-]+)\.(?P<pid>\d+)-[a-z0-9_]{8}\.tmp$")  # mkstemp's 8


def temp_file(path):
    """A new empty temporary file beside ``path`` (returned as a str) for an atomic write.

    Its name holds the host and pid of the writer and a random part, so concurrent writers
    never share one and :func:`remove_stale_temps` can tell a dead writer's leftovers from a
    live one's.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.{_host()}.{os.getpid()}-", suffix=".tmp")
    os.close(fd)
    os.chmod(tmp, user_file_mode())  # mkstemp's 0600 -> what a plain open() under the user's umask gives
    return tmp


def _pid_alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    return True


def remove_stale_temps(folder, *, recursive=True):
    """Delete the temporary files (:func:`temp_file`) under ``folder`` whose writer is dead.

    Only names of our pattern written on this host are considered, and only those whose pid
    no longer runs; a live writer's file (here or on another host) is left alone.  Returns
    the paths removed.
    """
    folder = Path(folder)
    if not folder.is_dir():
        return []
    host, removed = _host(), []
    for p in (folder.rglob(".*.tmp") if recursive else folder.glob(".*.tmp")):
        m = _TEMP.match(p.name)
        if m and m["host"] == host and int(m["pid"]) != os.getpid() and not _pid_alive(int(m["pid"])):
            p.unlink(missing_ok=True)
            removed.append(p)
    return removed


class CheckpointLock:
    """An exclusive lock on a run folder: two processes never write the same results at once.

    Uses ``fcntl.flock`` on ``.<name>.lock`` beside ``path`` (released by the kernel if the
    process dies), with the holder's pid written into it; a second process gets the one-line
    InputError ``OUT is in use by pid N`` (it does not wait).  ``skinfit fit --out``,
    ``skinfit fit --by``, ``skinfit population`` and campaigns take it on their output folder.
    ``shared=True`` is a reader's lock on the same file (``skinfit population`` and
    :func:`skinfit.load_groups` reading a run): any number of readers at once, none while a
    writer holds it, and no writer while one reads.  A folder where the lock file cannot be
    created (read-only) and does not exist has no writer: a reader proceeds without it.
    Where ``fcntl`` is unavailable the lock is a no-op.
    """

    def __init__(self, path, *, shared=False):
        self.path = Path(path)
        self.lock_path = self.path.with_name(f".{self.path.name}.lock")
        self.shared = bool(shared)
        self._fd = None

    def __enter__(self):
        if fcntl is None:  # pragma: no cover - not POSIX
            return self
        if not self.shared:
            self.lock_path.parent.mkdir(parents=True, exist_ok=True)
        tries = 0
        while True:
            fd = self._open()
            if fd is None:  # a reader of a folder it cannot write, with no lock file: no writer there
                return self
            try:
                fcntl.flock(fd, (fcntl.LOCK_SH if self.shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
            except OSError:
                try:
                    holder = os.read(fd, 32).decode(errors="replace").strip()
                finally:
                    os.close(fd)
                tries += 1
                if not holder and tries < 40:  # a reader leaving (it locks to tidy up) or a writer starting
                    time.sleep(0.025)
                    continue
                if self.shared:
                    raise InputError(self.path.parent, f"is being written by pid {holder or '?'} (lock "
                                     f"{self.lock_path.name}): wait for it to finish, then read it") from None
                who = f"is in use by pid {holder}" if holder else "is in use by another skinfit process (reading it)"
                raise InputError(self.path.parent, f"{who} (lock {self.lock_path.name}); wait for it to finish or "
                                 "use another --out") from None
            # the holder before us may have unlinked the file after we opened it: lock the live one
            try:
                same = os.stat(self.lock_path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        self._fd = fd
        if self.shared:  # a reader neither names itself nor tidies the writer's folder
            return self
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode())
        for stale in self.path.parent.glob(f".{self.path.name}.*.tmp"):  # left by a killed writer
            m = _TEMP.match(stale.name)
            if m and m["name"] == self.path.name:  # a temp file of ours (temp_file), never a file of like name
                stale.unlink(missing_ok=True)
        remove_stale_temps(self.path.parent, recursive=False)
        return self

    def _open(self):
        """A descriptor of the lock file (created unless this is a reader that cannot), or None."""
        try:
            return os.open(self.lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError:
            if not self.shared:
                raise
        try:
            return os.open(self.lock_path, os.O_RDONLY)
        except FileNotFoundError:
            return None

    def __exit__(self, *exc):
        if self._fd is None:
            return False
        if self.shared:  # the last reader removes the file it may have created
            try:
                fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                if os.stat(self.lock_path).st_ino == os.fstat(self._fd).st_ino:
                    self.lock_path.unlink()
            except OSError:  # another reader or a writer holds it now, or it is gone
                pass
        else:
            self.lock_path.unlink(missing_ok=True)
        os.close(self._fd)
        self._fd = None
        return False


def watch_parent(pid, interval=0.5):
    """In a worker process started by process ``pid`` (a campaign's fit worker, a report's
    figure worker): a daemon thread that ends the worker when its parent is no longer ``pid``
    (the parent was killed, even by SIGKILL, and the worker re-parented), so no worker goes on
    writing after the process that started it died."""

    def watch():
        while os.getppid() == pid:
            time.sleep(interval)
        os._exit(70)

    threading.Thread(target=watch, name="skinfit-parent-watch", daemon=True).start()
