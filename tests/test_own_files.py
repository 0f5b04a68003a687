"""Class: a tidy step deletes what it did not write. Every place skinfit removes or replaces a
file it finds (temporary files of killed writers, a lock's leftovers, a report's earlier
tables, its figures) touches only files it can show are its own; a user's files of like names
survive. (What a report folder's figures keep and redraw: tests/test_figure_folder.py.)"""

import os
import subprocess
import sys
import warnings

import pandas as pd
import pytest
from popdata import write_population

import skinfit
from skinfit import plots
from skinfit.analysis.groups import fit_by
from skinfit.inference.checkpoint import CheckpointLock, _host, remove_stale_temps, temp_file
from skinfit.report import figures
from skinfit.report import html as report


def _dead_pid():
    """The pid of a process that has ended (so a temp file named with it is a dead writer's)."""
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    return int(proc.stdout)


def test_class_tidy_removes_only_its_own_temp_files(tmp_path):
    """A killed writer's temporary file (named by :func:`temp_file`: host, pid, mkstemp's random
    part) is removed; a user's files with like names are not, whatever they end in."""
    pid = _dead_pid()
    ours = tmp_path / f".fit.nc.{_host()}.{pid}-a1b2c3d4.tmp"
    ours.write_bytes(b"half a fit")
    user = {tmp_path / f".fit.nc.{_host()}.{pid}-backup.tmp": b"a user's backup",
            tmp_path / f".notes.{_host()}.{pid}-Draft_Version_2.tmp": b"notes",
            tmp_path / ".thesis.tex.tmp": b"\\documentclass"}
    for path, data in user.items():
        path.write_bytes(data)
    live = temp_file(tmp_path / "index.json")  # this process's: alive, kept
    assert remove_stale_temps(tmp_path) == [ours]
    assert all(p.read_bytes() == data for p, data in user.items()) and os.path.exists(live)


def test_class_tidy_a_lock_removes_only_its_own_temp_files(tmp_path):
    """Taking a run folder's lock removes the temporary files a killed writer of its target left,
    not a user's files whose names merely begin and end alike."""
    ours = tmp_path / f".checkpoint.h5.{_host()}.{_dead_pid()}-zz99yy88.tmp"
    ours.write_bytes(b"old")
    user = tmp_path / ".checkpoint.h5.my copy.tmp"
    user.write_bytes(b"the user's copy")
    with CheckpointLock(tmp_path / "checkpoint.h5"):
        pass
    assert not ours.exists() and user.read_bytes() == b"the user's copy"


def test_class_tidy_a_report_removes_only_tables_it_wrote(ea_fit, tmp_path, no_figures):
    """A report removes its earlier tables that the new page does not show, but not a file the
    user has put in the place of one (other content) since."""
    table = pd.DataFrame({"log_z": [512.25, 498.125], "log_z_se": [0.03125, 0.0625]},
                         index=pd.Index(["electroadhesion", "electroadhesion_coulomb"], name="model"))
    out = tmp_path / "rep"
    report.write_report([ea_fit], out, comparison=table)
    report.write_report([ea_fit], out)  # no comparison now: its table goes
    assert not (out / "comparison.csv").exists()
    report.write_report([ea_fit], out, comparison=table)
    (out / "comparison.csv").write_text("model,my own numbers\nA,1\n")  # the user's file now
    report.write_report([ea_fit], out)
    assert (out / "comparison.csv").read_text() == "model,my own numbers\nA,1\n"


@pytest.mark.parametrize("folder", ["notes", "subject-S01-0123abcd"])
def test_class_tidy_a_run_by_groups_looks_only_in_its_own_folders(tmp_path, folder):
    """`fit --by` removes a killed run's temporary files from its index's folder and its groups'
    folders only: not from a user's sub-folder of --out (the old code searched --out's whole tree)."""
    path, _ = write_population(tmp_path / "data", n_subjects=2)
    out = tmp_path / "run"
    keep = out / folder / f".draft.txt.{_host()}.{_dead_pid()}-abcdefgh.tmp"
    keep.parent.mkdir(parents=True)
    keep.write_text("a user's file")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        fit_by("electroadhesion_coulomb", path, "subject", out, seed=1, ess_target=50, max_steps=300)
    assert keep.read_text() == "a user's file"


def test_class_tidy_a_report_removes_only_figures_it_wrote_and_can_prove_it_wrote(ea_fit, tmp_path, monkeypatch):
    """A report's figures/ holding the user's files (any name, one shaped like a figure's, a
    figure the user edited, a record forged to list them): drawing, keeping, dropping a figure
    the page no longer shows and a figure that fails leave every one of them as it was. The
    figure dropped is removed where it still holds what the report wrote (its PDF), kept
    where the user edited it (its PNG). Issue 39 point 9 (the figure store it replaced
    removed files it never wrote)."""
    import hashlib
    import json

    monkeypatch.setattr(figures, "MAX_FIGURE_WORKERS", 1)
    figdir = tmp_path / "figures"
    figdir.mkdir()
    mine = {figdir / "mine.png": b"\x89PNG the user's figure", figdir / "mine.pdf": b"%PDF the user's",
            figdir / "fit_plot_ppc.png": b"\x89PNG shaped like a figure of the report",
            figdir / "notes" / "fit_plot_trace.png": b"in a sub-folder", figdir / ".hidden.json": b"{}"}
    for path, data in mine.items():
        path.parent.mkdir(exist_ok=True)
        path.write_bytes(data)

    def jobs(*funcs):
        return [{"fit": 0, "func": f, "args": (), "path": figdir / f"fit_{f}.png"} for f in funcs]

    def unchanged():
        return {p: p.read_bytes() for p in mine} == mine

    assert figures.render_figures([ea_fit], jobs("plot_prior_posterior", "plot_trace"), figdir) == [None, None]
    assert figures.render_figures([ea_fit], jobs("plot_prior_posterior", "plot_trace"), figdir) == [None, None]
    assert unchanged()
    trace = figdir / "fit_plot_trace.png"
    trace.write_bytes(trace.read_bytes() + b"the user's annotation")  # now the user's
    mine[trace] = trace.read_bytes()
    doc = json.loads((figdir / ".figures.json").read_text())
    record = doc["figures"]["fit_plot_prior_posterior.png"]
    doc["figures"]["mine.png"] = doc["figures"]["fit_plot_ppc.png"] = record  # listed, but not what it wrote there
    (figdir / ".figures.json").write_text(json.dumps(doc))

    def broken(*args, **kwargs):
        raise RuntimeError("no predictive check today")

    monkeypatch.setattr(plots, "plot_ppc", broken)
    errors = figures.render_figures([ea_fit], jobs("plot_prior_posterior", "plot_ppc"), figdir)
    assert errors[0] is None and "no predictive check today" in errors[1]
    assert unchanged(), "the user's files, and the figure the user edited, are as they were"
    assert not (figdir / "fit_plot_trace.pdf").exists(), "the dropped figure's PDF, as written, is removed"
    kept = json.loads((figdir / ".figures.json").read_text())["figures"]
    assert set(kept) == {"fit_plot_prior_posterior.png"}
    assert kept["fit_plot_prior_posterior.png"]["files"][".png"]["sha256"] == hashlib.sha256(
        (figdir / "fit_plot_prior_posterior.png").read_bytes()).hexdigest()
