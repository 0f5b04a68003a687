"""Every subcommand of the command line, every option, hostile values (issue 39, point 14).

The subcommands and their options are read from the parser (``skinfit --help``), so a new option
is fuzzed the day it is added.  Each generated case runs ``skinfit.apps.cli.main`` in-process on a
valid command line with one argument replaced by a hostile value (negative, zero, huge, NaN,
empty, unicode, a missing path, a folder, /dev/null, /dev/zero, a FIFO); the first expensive
step of every command is replaced by a stand-in that raises ``_WorkStarted``.  Properties: the
exit status is 0, 1, 2 or 3 (or the work started), stderr holds no traceback and at most one
``error:`` line, the last; a value that can never be valid for its kind of argument (a number,
a folder to write, a file to read) is refused before any work.  A few cases run as a real
subprocess.
"""

import argparse
import contextlib
import importlib
import io
import os
import re
import signal
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from popdata import write_population
from recordings import ISSUE_RIG

from skinfit.apps.cli import build_parser, main

MODEL, DATASET = "electroadhesion_coulomb", "electroadhesion_synthetic"
ERROR_LINE = re.compile(r"^skinfit(?: [\w-]+){0,2}: error: ")  # "skinfit dataset init: error: ..."


class _WorkStarted(Exception):
    """Raised by the stand-ins for the first expensive step of each command."""


def _work(*args, **kwargs):
    raise _WorkStarted


#: module -> names replaced by _work: the first step of each command that costs more than reading
STAND_INS = {"skinfit.inference.run": ["find_map"], "skinfit.analysis.compare": ["evidence"], "skinfit.report.html": ["write_report"],
             "skinfit.apps.campaign": ["_run_locked"], "skinfit.analysis.population.population": ["run_gibbs", "reweight"],
             "skinfit.analysis.sbc": ["_map"], "skinfit.apps.demo": ["ProcessPoolExecutor"],
             "skinfit.analysis.design.plan": ["batch_eig", "eig_nmc", "greedy_plan", "laplace_design"],
             "skinfit.io.recordings.ingest": ["open_trials"]}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A saved fit, a run by groups of two subjects, a campaign file, a candidate grid, a FIFO."""
    import skinfit
    from skinfit.analysis.groups import fit_by

    root = tmp_path_factory.mktemp("cli_fuzz")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = skinfit.fit(MODEL, DATASET, rng=3, ess_target=50, max_steps=400)
        fit.save(root / "fit" / "fit.nc")
        data, _ = write_population(root, n_subjects=2, rows=6)
        fit_by(MODEL, str(data), "subject", root / "by", seed=2, ess_target=50, max_steps=400)
    (root / "grid.toml").write_text('[grid.normal_force]\nunit = "mN"\nfrom = 200\nto = 2000\nnum = 4\n'
                                    '[grid.voltage]\nunit = "V"\nvalues = [0, 100]\n')
    (root / "camp.toml").write_text(f'schema_version = 1\nseed = 1\nout = "camp_out"\nmodels = ["{MODEL}"]\n'
                                    f'datasets = ["{DATASET}"]\nby = ["voltage"]\n[fit]\ness = 50\nmax_steps = 400\n')
    (root / "rig.toml").write_text(ISSUE_RIG)
    scipy.io.savemat(root / "S1_0V_1.mat", {"data": np.zeros((100, 3))})
    os.mkfifo(root / "fifo")
    (root / "folder").mkdir()
    (root / "file.txt").write_text("x")
    (root / "lab.csv").write_text("# rig export\nNormal force (mN);Ft;Voltage (V)\n200,5;90,25;0\n400;180,5;100\n")
    return root


def _base(cmd, root, out):
    """A valid command line of ``cmd`` (its work replaced by the stand-ins)."""
    return {"models": [], "datasets": [], "priors": [MODEL],
            "fit": [MODEL, DATASET, "--out", str(out)],
            "compare": [str(root / "fit"), str(root / "fit" / "fit.nc")],
            "report": [str(root / "fit"), "--out", str(out)],
            "campaign": [str(root / "camp.toml")],
            "population": [str(root / "by"), "--out", str(out)],
            "sbc": [MODEL, "--n-sims", "2"],
            "demo": ["--out", str(out), "--dataset", DATASET],
            "design": [MODEL, "--candidates", str(root / "grid.toml")],
            "dataset init": [str(root / "lab.csv"), "--model", MODEL, "--out", str(out),
                             "--column", "Ft=tangential_force:mN"],
            "ingest": [str(root / "S1_0V_1.mat"), "--rig", str(root / "rig.toml"), "--out", str(out)]}[cmd]


def _arguments():
    """(command, option string or positional index, action) for every argument that takes a value."""
    parser = build_parser()
    subs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    out = [(cmd, "--path", None) for cmd in ("models", "fit")]  # the global option
    commands = {}
    for cmd, sub in subs.choices.items():  # a command of commands (dataset init): each of them
        nested = next((a for a in sub._actions if isinstance(a, argparse._SubParsersAction)), None)
        commands.update({f"{cmd} {c}": s for c, s in nested.choices.items()} if nested else {cmd: sub})
    for cmd, sub in commands.items():
        positional = [a for a in sub._actions if not a.option_strings]
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction) or action.nargs == 0:
                continue
            key = (max(action.option_strings, key=len) if action.option_strings
                   else positional.index(action))
            out.append((cmd, key, action))
    return out


ARGUMENTS = _arguments()
NUMBER_TYPES = {"parse", "_positive_float", "int", "float"}
#: dests that name a file or folder skinfit reads, and folders it writes
INPUTS = {"model", "dataset", "runs", "campaign", "candidates", "from_fit", "priors", "baseline", "run", "file",
          "raw", "rig"}
FOLDERS = {"out", "report"}


def _kind(action):
    if action is None:
        return "search folder"
    if action.dest in FOLDERS:
        return "folder"
    if action.dest in INPUTS:
        return "input"
    if getattr(action.type, "__name__", None) in NUMBER_TYPES and action.choices is None:
        return "number"
    return "text"


#: hostile values; "@X" names a path of the fixture (FIFO, folder, a file where a folder is meant)
HOSTILE = ["-1", "0", "-0", "1e400", "nan", "inf", "-inf", "1000000000000", "99999999999999999999999", "", " ",
           "\u00b5\u202e", "0x10", "1.5", "x,y", "=", "a=b", ",", "-", "/nonexistent/x", "/dev/null", "/dev/zero",
           "@fifo", "@folder", "@file.txt/sub", "\n"]


def _never_valid(kind, value):
    """Values that no argument of this kind accepts (so they must be refused before any work)."""
    if kind == "number":
        try:
            number = float(value)
        except ValueError:
            return not value.strip().lower().startswith(("0x", "0o", "0b")) or value.strip() == ""
        return not (number == number and abs(number) != float("inf")) or number < 0 or value.strip() == ""
    if kind == "folder":
        return value.strip() == "" or value in ("/dev/null", "/dev/zero", "@fifo", "@file.txt/sub")
    if kind == "input":
        return value.strip() == "" or value in ("/nonexistent/x", "/dev/null", "/dev/zero", "@fifo", "@folder",
                                                "@file.txt/sub")
    return False


def _argv(cmd, key, value, root, out):
    argv = list(_base(cmd, root, out))
    if key == "--path":
        return ["--path", value, *cmd.split(), *argv]
    if isinstance(key, int):
        positional = [i for i, a in enumerate(argv)
                      if not a.startswith("--") and (i == 0 or not argv[i - 1].startswith("--"))]
        if key < len(positional):
            argv[positional[key]] = value
        else:
            argv.insert(len(positional), value)
    elif key in argv:
        argv[argv.index(key) + 1] = value
    else:
        argv += [key, value]
    return [*cmd.split(), *argv]


@contextlib.contextmanager
def _deadline(seconds):
    """A hang (a FIFO waited on, /dev/zero read) fails the case instead of the suite."""
    def expired(*args):
        raise TimeoutError(f"no answer in {seconds} s")

    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@pytest.fixture
def stand_ins(monkeypatch, inputs):
    for module, names in STAND_INS.items():
        mod = importlib.import_module(module)
        for name in names:
            monkeypatch.setattr(mod, name, _work)
    monkeypatch.chdir(inputs)
    return inputs


def _run(argv):
    """(exit status or "work", stderr) of ``skinfit ARGV`` in this process."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            with _deadline(60):
                code = main(argv)
        except SystemExit as exc:
            code = exc.code
        except _WorkStarted:
            code = "work"
    return code, err.getvalue()


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(argument=st.sampled_from(ARGUMENTS),
       value=st.one_of(st.sampled_from(HOSTILE), st.text(max_size=6), st.integers().map(str),
                       st.floats().map(repr)))
def test_class_cli_every_option_hostile_value_one_line_error_or_valid(stand_ins, argument, value):
    cmd, key, action = argument
    if "\0" in value:
        return  # not a possible command-line argument
    root = stand_ins
    kind = _kind(action)
    value_at = str(root / value[1:]) if value.startswith("@") else value
    with tempfile.TemporaryDirectory(dir=root) as tmp:
        argv = _argv(cmd, key, value_at, root, Path(tmp) / "out")
        code, err = _run(argv)
    assert "Traceback" not in err, (argv, err)
    assert code in (0, 1, 2, 3, "work"), (argv, code, err)
    errors = [line for line in err.splitlines() if ": error: " in line]
    if code in (1, 2) and errors:
        assert len(errors) == 1 and ERROR_LINE.match(errors[0]) and err.rstrip().endswith(errors[0]), (argv, err)
    if code == 2:
        assert errors, (argv, err)  # a refusal says why
    if _never_valid(kind, value):
        assert code == 2, (argv, code, err)  # refused before any work


@pytest.mark.parametrize("argv, match", [
    (["fit", MODEL, DATASET, "--out", "@fifo"], r"/fifo: is a FIFO: --out names the folder the results are written"),
    (["sbc", MODEL, "--n-sims", "2", "--out", "/dev/null"], r"/dev/null: is a device: --out names the folder"),
    (["report", "@fit", "--out", "@file.txt/sub"], r"/file\.txt/sub: is inside .*/file\.txt, which is a file: --out "
                                                    r"names the folder the report is written into"),
    (["fit", MODEL, DATASET, "--out", ""], r"argument --out: expected a value \(got ''\)"),
    (["design", MODEL, "--candidates", "@grid.toml", "--from", ""], r"argument --from: expected a value \(got ''\)"),
    (["priors", "x\x1ey\u2028"], r"^skinfit: error: x\\x1ey\\u2028: no such prior"),
    (["compare", "@fifo", "@fit"], r"/fifo: is a FIFO: expected the fit file"),
    (["population", "/dev/zero"], r"/dev/zero: is a device: expected the index\.json of a run"),
    (["population", "@by", "--seed", "-1"], r"argument --seed: expected a seed"),
    (["design", MODEL, "--candidates", "@grid.toml", "--from", "@fifo"], r"/fifo: is a FIFO: expected the fit file"),
    (["demo", "--dataset", "nope", "--out", "@demo_out"], r"demo: dataset: no shipped dataset 'nope' in the demo"),
    (["fit", MODEL, DATASET, "--out", "@fit_out", "--priors", ""], r"argument --priors: expected a value"),
])
def test_class_cli_hostile_values_found_by_the_fuzz(stand_ins, argv, match):
    """The cases the generated test found on the code before this change (tracebacks, hangs,
    MemoryError, a FIFO waited on, /dev/null taken for a folder after an SBC run), pinned."""
    root = stand_ins
    argv = [str(root / a[1:]) if a.startswith("@") else a for a in argv]
    code, err = _run(argv)
    assert code == 2, (argv, code, err)
    assert "Traceback" not in err and re.search(match, err.strip().splitlines()[-1]), err


@pytest.mark.parametrize("argv, option", [
    pytest.param(["campaign", "@camp.toml", "--scheduler", "banana"], "--scheduler"),
    pytest.param(["design", MODEL, "--candidates", "@grid.toml", "--n", "1000000"], "--n"),
    pytest.param(["design", MODEL, "--candidates", "@grid.toml", "--discriminate", "/nonexistent/x"], "nonexistent"),
    pytest.param(["population", "@by", "--params", ","], "--params"),
    pytest.param(["--path", "/nonexistent/x", "models"], "/nonexistent/x"),
    pytest.param(["--path", "/dev/null", "models"], "/dev/null"),
], ids=lambda v: " ".join(v) if isinstance(v, list) else None)
def test_class_cli_hostile_values_refused_before_work(stand_ins, argv, option):
    """Hostile values the generated test found in design, population, campaign and the search
    path: each refused in one line before any work."""
    argv = [str(stand_ins / a[1:]) if a.startswith("@") else a for a in argv]
    code, err = _run(argv)
    assert code == 2 and option in err, (code, err)


@pytest.mark.parametrize("argv", [
    ["fit", MODEL, DATASET, "--out", "/dev/null/run"],
    ["population", "/dev/zero"],
    ["compare", "/dev/null", "/nonexistent"],
])
def test_class_cli_subprocess_hostile_values_one_line_no_traceback(argv):
    proc = subprocess.run([sys.executable, "-m", "skinfit", *argv], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert "Traceback" not in proc.stderr and len(lines) == 1 and ERROR_LINE.match(lines[0]), proc.stderr
