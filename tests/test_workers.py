"""Worker processes: every exception a worker can raise crosses back to the parent intact, a
worker that dies fails only its own item, BLAS/OpenMP threads are limited to one per worker
unless the user says otherwise, and the executor a user names is checked before any work."""

import ast
import builtins
import importlib
import inspect
import multiprocessing
import os
import pickle
import pkgutil
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
from worker_jobs import die_on, instance, raise_instance, threads_in_worker, zero_force

import skinfit
from skinfit.errors import InputError, MissingDependency, Portable, WorkerError, error_line, portable
from skinfit.inference.workers import THREAD_VARIABLES, check_scheduler, run_isolated


def _modules():
    """Every module of the package (its __main__ runs the CLI when imported: left out)."""
    names = [m.name for m in pkgutil.walk_packages(skinfit.__path__, "skinfit.") if not m.name.endswith("__main__")]
    return [importlib.import_module(n) for n in names]


def _raised(module):
    """The exception classes a module's ``raise X(...)`` / ``raise mod.X`` statements name."""
    found = set()
    for node in ast.walk(ast.parse(inspect.getsource(module))):
        if isinstance(node, ast.Raise) and node.exc is not None:
            expr = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
            parts = []
            while isinstance(expr, ast.Attribute):
                parts.insert(0, expr.attr)
                expr = expr.value
            if not isinstance(expr, ast.Name):
                continue
            obj = vars(module).get(expr.id, getattr(builtins, expr.id, None))
            for part in parts:
                obj = getattr(obj, part, None)
            if inspect.isclass(obj) and issubclass(obj, BaseException):
                found.add(obj)
    return found


def exception_classes():
    """Every exception class (warnings included: ``-W error`` raises them) that a skinfit module
    defines, and every class its code raises: a class added to skinfit is tested here without
    a word more."""
    classes = set()
    for module in _modules():
        classes |= {obj for obj in vars(module).values() if inspect.isclass(obj) and issubclass(obj, BaseException)
                    and obj.__module__ == module.__name__}
        classes |= _raised(module)
    return sorted(classes, key=lambda c: f"{c.__module__}.{c.__qualname__}")


CLASSES = exception_classes()


def _same(a, b):
    assert type(a) is type(b)
    assert str(a) == str(b) and a.args == b.args
    assert pickle.dumps(vars(a)) == pickle.dumps(vars(b))  # every attribute (MAPError.result, InputError.row)


def test_the_classes_found_include_those_a_worker_raises():
    from skinfit.inference.optimize import MAPError

    assert {InputError, MissingDependency, MAPError, WorkerError, skinfit.ConvergenceWarning, ValueError} <= set(CLASSES)


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: f"{c.__module__}.{c.__qualname__}")
def test_exception_class_pickles_with_its_message_and_attributes(cls):
    exc = instance(cls)
    _same(exc, pickle.loads(pickle.dumps(exc)))


@pytest.fixture(scope="module")
def spawned():
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        yield pool


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: f"{c.__module__}.{c.__qualname__}")
def test_exception_class_raised_in_a_worker_process_reaches_the_parent(spawned, cls):
    """As a campaign's pool sees it: the worker's exception, not BrokenProcessPool."""
    future = spawned.submit(raise_instance, cls.__module__, cls.__qualname__)
    _same(future.exception(timeout=120), instance(cls))


def test_map_error_crosses_with_its_result_and_message(tmp_path, spawned):
    """The MAP of data with a zero normal force (impossible for the electroadhesion model) fails
    with MAPError(message, result): it reaches the parent whole, the rows it names included."""
    from skinfit.inference.optimize import MAPError

    with pytest.raises(MAPError) as info:
        skinfit.fit("electroadhesion", zero_force(tmp_path), rng=1, progress=False)
    back = pickle.loads(pickle.dumps(info.value))
    _same(back, info.value)
    assert "data row(s) 1 (normal_force = 0" in str(back)
    assert np.isnan(back.result.theta).all() and back.result.evaluations == info.value.result.evaluations
    assert error_line(back).startswith("MAPError: ") and "\n" not in error_line(back)


class _Unpicklable(Exception):
    def __init__(self, message):
        super().__init__(message)
        self.callback = lambda: None  # a lambda does not pickle


class _Strict(Portable, RuntimeError):
    """A class of the kind MAPError was: its ``__init__`` takes other arguments than ``args``."""

    def __init__(self, a, *, b):
        super().__init__(f"{a}/{b}")
        self.a, self.b = a, b


def test_an_exception_that_cannot_cross_becomes_a_worker_error_with_its_class_and_message():
    back = portable(_Unpicklable("bad\nthing"))
    assert isinstance(back, WorkerError) and back.kind == "_Unpicklable" and str(back) == "bad\nthing"
    assert error_line(back) == "_Unpicklable: bad thing"
    exc = InputError("f.csv", "x", row=2)
    assert portable(exc) is exc  # one that crosses is raised as itself


def test_portable_mixin_rebuilds_any_init_signature_without_calling_it():
    back = pickle.loads(pickle.dumps(_Strict(1, b=2)))
    assert type(back) is _Strict and (back.a, back.b, str(back), back.args) == (1, 2, "1/2", ("1/2",))


# ---- a worker that dies fails only its own item --------------------------------------------

def test_a_worker_that_dies_fails_only_its_own_item():
    """Item 1 of 9 kills its worker: the 8 others give their results, item 1 a one-line
    BrokenProcessPool error of its own."""
    items = {i: f"x{i}" for i in range(9)}
    items[1] = "die"
    got = {}
    run_isolated(die_on, items, 2,
                 lambda key, result=None, error=None: got.update({key: error if error is not None else result}))
    assert {k: v for k, v in got.items() if k != 1} == {i: f"x{i}x{i}" for i in range(9) if i != 1}
    assert isinstance(got[1], WorkerError) and got[1].kind == "BrokenProcessPool"
    assert error_line(got[1]).startswith("BrokenProcessPool: its worker process died")


# ---- threads ---------------------------------------------------------------------------------

def _in_spawned(monkeypatch, env, threads):
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(threads_in_worker, threads).result(timeout=120)


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="one core: every library has one thread anyway")
def test_worker_thread_limit_is_one_unless_the_user_sets_it(monkeypatch):
    inside, after = _in_spawned(monkeypatch, {}, None)
    assert inside == 1 and after > 1  # limited while fitting, the libraries' own setting restored after
    assert _in_spawned(monkeypatch, {}, 2)[0] == 2  # --threads 2
    assert _in_spawned(monkeypatch, {"OPENBLAS_NUM_THREADS": "2"}, None)[0] == 2  # the user's variable rules


# ---- the executor is checked before any work ---------------------------------------------------

@pytest.mark.parametrize("value", ["banana", "banana://host:8786", "tcp://host", "tcp://:8786", "tcp://host:port",
                                   "tcp://host:99999", "", "http://host:80", "tcp://host:8786/x", 8786,
                                   "tcp://ho\nst:8786", "tcp://host:8786\t", " tcp://host:8786"])
def test_scheduler_that_is_no_address_is_refused_in_one_line(value):
    with pytest.raises(InputError, match=r"^--scheduler: expected 'local' or a Dask scheduler's address") as info:
        check_scheduler(value)
    assert "\n" not in str(info.value)


def test_scheduler_addresses_dask_takes_pass():
    for value in (None, "local", "tcp://127.0.0.1:8786", "tls://scheduler.example:8786", "tcp://[::1]:8786"):
        assert check_scheduler(value) == value


def test_dask_scheduler_without_dask_installed_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    for value in ("local", "tcp://127.0.0.1:8786"):
        with pytest.raises(MissingDependency, match=r"^distributed is not installed: install skinfit\[dask\]"):
            check_scheduler(value)
    assert check_scheduler(None) is None  # local processes need no Dask


# ---- the module imports where ``resource`` does not exist (Windows) -----------------------------

def test_campaign_imports_without_the_unix_resource_module():
    code = ("import sys; sys.modules['resource'] = None\n"  # as on Windows: import resource -> ImportError
            "import skinfit.apps.campaign as c, math; assert c.resource is None and math.isnan(c._peak_rss_mb()); "
            "print('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


def test_forkable_only_without_other_threads():
    """In a new interpreter (no thread but the main one): forkable; with a thread started, not;
    after it ends, forkable again."""
    code = ("import threading; from skinfit.inference.workers import forkable\n"
            "a = forkable(); e = threading.Event(); t = threading.Thread(target=e.wait); t.start()\n"
            "b = forkable(); e.set(); t.join(); print(a, b, forkable())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    expected = "True False True" if "fork" in multiprocessing.get_all_start_methods() else "False False False"
    assert out.stdout.strip() == expected, out.stderr


@pytest.mark.parametrize("entry", ["run_sbc", "run_demo"])
@pytest.mark.parametrize("jobs", [0, -2, "2", 1.5, True])
def test_process_counts_of_the_python_entry_points_are_checked_before_any_work(entry, jobs, tmp_path):
    from skinfit.analysis.sbc import run_sbc
    from skinfit.apps.demo import run_demo

    call = {"run_sbc": lambda: run_sbc("electroadhesion_coulomb", n_sims=2, jobs=jobs),
            "run_demo": lambda: run_demo(tmp_path / "d", tmp_path / "r", jobs=jobs)}[entry]
    with pytest.raises(InputError, match=r"jobs: expected a whole number >= 1 \(got "):
        call()
    assert not list(tmp_path.iterdir())
