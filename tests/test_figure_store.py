"""The figure store: a figure is drawn once per content, whichever report folder asks for it,
and never reused for other content, other code, an altered stored file or a user's own model."""

import hashlib
import json
from pathlib import Path

import pytest

from skinfit.report import figure_store

from skinfit import plots

from skinfit.report import html as report
from skinfit.results.fit import load_fit


@pytest.fixture
def store(tmp_path, monkeypatch):
    """The store's own folder (its entries) under the folder $SKINFIT_FIGURE_STORE names."""
    folder = tmp_path / "store"
    monkeypatch.setenv("SKINFIT_FIGURE_STORE", str(folder))
    return folder / figure_store.FOLDER


@pytest.fixture
def drawn(monkeypatch):
    """The indices of the figure jobs drawn (one worker: drawn in this process)."""
    calls = []
    original = report._render_one
    monkeypatch.setattr(report, "MAX_FIGURE_WORKERS", 1)
    monkeypatch.setattr(report, "_render_one", lambda i: calls.append(i) or original(i))
    return calls


def _render(fit, folder, func="plot_prior_posterior"):
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"fit_{func}.png"
    errors = report.render_figures([fit], [{"fit": 0, "func": func, "args": (), "path": path}], folder)
    assert errors == [None]
    return path


def _digest(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def test_a_figure_is_drawn_once_per_content_whichever_folder(ea_fit, store, drawn, tmp_path):
    first = _render(ea_fit, tmp_path / "a")
    assert drawn == [0]
    second = _render(ea_fit, tmp_path / "b")
    assert drawn == [0], "the same fit's figure in a new report folder is copied, not drawn"
    for suffix in (".png", ".pdf"):
        assert _digest(first.with_suffix(suffix)) == _digest(second.with_suffix(suffix))
    assert len(list(store.glob("??/*.json"))) == 1

    ea_fit.save(tmp_path / "fit.nc")
    other = load_fit(tmp_path / "fit.nc")
    name = next(iter(other.group("posterior").data_vars))
    other.idata["posterior"][name].values[0, 0] *= 1.5  # one draw of one walker changed
    _render(other, tmp_path / "c")
    assert drawn == [0, 0], "other content is drawn, never taken from the store"


def test_an_altered_stored_figure_is_drawn_again(ea_fit, store, drawn, tmp_path):
    _render(ea_fit, tmp_path / "a")
    (png,) = store.glob("??/*.png")
    png.write_bytes(png.read_bytes()[:-10])  # a damaged entry (truncated)
    again = _render(ea_fit, tmp_path / "b")
    assert drawn == [0, 0]
    assert _digest(png) == _digest(again), "the entry is written whole again"


def test_a_replaced_plot_function_draws_again(ea_fit, store, drawn, tmp_path, monkeypatch):
    _render(ea_fit, tmp_path / "a")
    original = plots.plot_prior_posterior
    monkeypatch.setattr(plots, "plot_prior_posterior", lambda fit, *a, **k: original(fit, *a, **k))
    _render(ea_fit, tmp_path / "b")
    assert drawn == [0, 0]


def test_only_unchanged_shipped_models_are_stored(ea_fit, tmp_path):
    assert figure_store.storable(ea_fit)
    ea_fit.save(tmp_path / "fit.nc")
    edited = load_fit(tmp_path / "fit.nc")
    edited.idata.attrs["model_sha256"] = "0" * 64  # fitted with another card of that name
    assert not figure_store.storable(edited)


def test_turned_off_stores_nothing(ea_fit, tmp_path, drawn, monkeypatch):
    monkeypatch.setenv("SKINFIT_FIGURE_STORE", "off")
    assert figure_store.store_dir() is None
    _render(ea_fit, tmp_path / "a")
    _render(ea_fit, tmp_path / "b")
    assert drawn == [0, 0]


def test_the_store_is_trimmed_least_recently_used_first(store, monkeypatch, tmp_path):
    import os

    src = tmp_path / "fig.png"
    for k, stem in enumerate(("old", "used", "new")):
        src.write_bytes(bytes([k]) * 4000)
        src.with_suffix(".pdf").write_bytes(bytes([k]) * 4000)
        digest = hashlib.sha256(stem.encode()).hexdigest()
        figure_store.put(digest, src)
        os.utime(store / digest[:2] / f"{digest}.json", (1e9 + k, 1e9 + k))
    used = hashlib.sha256(b"used").hexdigest()
    assert figure_store.fetch(used, tmp_path / "copy.png")  # now the most recently used
    monkeypatch.setenv("SKINFIT_FIGURE_STORE_MB", str(17000 / 2**20))  # room for two entries
    figure_store.trim()
    kept = {p.stem for p in store.glob("??/*.json")}
    assert kept == {used, hashlib.sha256(b"new").hexdigest()}
    assert not list(store.glob(f"??/{hashlib.sha256(b'old').hexdigest()}*"))


def test_storable_wherever_the_process_runs(ea_fit, tmp_path, monkeypatch):
    """The shipped card is recognised by its location, not by a path relative to the
    working folder (a report run from any folder)."""
    monkeypatch.chdir(tmp_path)
    assert figure_store.storable(ea_fit)


def test_a_comparison_chart_is_copied_into_a_new_report_folder(ea_fit, store, tmp_path, monkeypatch):
    """A model-comparison chart depends on its table alone: drawn once, then copied from the
    store into another report's folder; another table is drawn."""
    import pandas as pd

    calls = []
    original = plots.plot_comparison
    monkeypatch.setattr(report, "MAX_FIGURE_WORKERS", 1)  # drawn in this process, where calls are counted
    monkeypatch.setattr(plots, "plot_comparison", lambda table: calls.append(1) or original(table))
    table = pd.DataFrame({"log_z": [512.25, 498.125], "log_z_se": [0.03125, 0.0625]},
                         index=pd.Index(["electroadhesion", "electroadhesion_coulomb"], name="model"))
    report.write_report([ea_fit], tmp_path / "a", comparison=table)
    report.write_report([ea_fit], tmp_path / "b", comparison=table)
    assert len(calls) == 1
    first, copied = (tmp_path / name / "figures" / "comparison.png" for name in "ab")
    assert _digest(first) == _digest(copied)
    report.write_report([ea_fit], tmp_path / "c", comparison=table.assign(log_z=[512.25, 499.0]))
    assert len(calls) == 2


# ---- class: a cache deletes what it did not write ---------------------------------------------
def _user_files(folder):
    """A folder of the user's: a large PDF, files in two-letter sub-folders (as the store's
    entries are named), one set shaped exactly like a stored entry, with a record of its
    sha256s. Returns {path: bytes}."""
    folder.mkdir(parents=True, exist_ok=True)
    files = {folder / "thesis.pdf": b"%PDF-1.7 " + bytes(range(256)) * 64,
             folder / "ab" / "figure.png": b"\x89PNG user figure", folder / "ab" / "notes.json": b'{"mine": 1}',
             folder / "cd" / "paper.pdf": b"%PDF user paper", folder / "summary.csv": b"a,b\n1,2\n"}
    digest = hashlib.sha256(b"looks like a stored entry").hexdigest()
    entry = {folder / digest[:2] / f"{digest}{s}": f"user {s}".encode() for s in (".png", ".pdf")}
    files |= entry
    files[folder / digest[:2] / f"{digest}.json"] = json.dumps(
        {p.suffix: hashlib.sha256(b).hexdigest() for p, b in entry.items()}).encode()
    for path, data in files.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    return files


def _unchanged(files):
    return {p: p.read_bytes() if p.is_file() else None for p in files} == files


def test_class_cache_deletes_only_what_it_wrote_user_files_survive_every_operation(ea_fit, tmp_path, monkeypatch):
    """$SKINFIT_FIGURE_STORE pointed at a folder of the user's files: storing, reusing and
    trimming figures (to 0 MiB too) leave every one of them as it was. Before: trimming removed
    every .png/.pdf/.json in any two-letter sub-folder, and the 'least recently used' user files
    first."""
    mine = tmp_path / "papers"
    files = _user_files(mine)
    monkeypatch.setenv("SKINFIT_FIGURE_STORE", str(mine))
    monkeypatch.setattr(report, "MAX_FIGURE_WORKERS", 1)
    _render(ea_fit, tmp_path / "a")  # drawn and stored
    _render(ea_fit, tmp_path / "b")  # reused
    assert _unchanged(files)
    monkeypatch.setenv("SKINFIT_FIGURE_STORE_MB", "0")  # every report now trims the store to nothing
    _render(ea_fit, tmp_path / "c")
    _render(ea_fit, tmp_path / "d", func="plot_rank")
    assert _unchanged(files)


def test_class_cache_trims_its_own_entries_and_never_an_altered_file(ea_fit, store, tmp_path, monkeypatch):
    """Trimming to 0 MiB removes every entry the store wrote, but a file the user put in the
    place of a stored one (other content) stays: the store removes only what it can prove it wrote."""
    src = tmp_path / "fig.png"
    digests = [hashlib.sha256(k.encode()).hexdigest() for k in ("one", "two")]
    for k, digest in enumerate(digests):
        src.write_bytes(bytes([k]) * 3000)
        src.with_suffix(".pdf").write_bytes(bytes([k]) * 3000)
        figure_store.put(digest, src)
    altered = store / digests[1][:2] / f"{digests[1]}.png"
    altered.write_bytes(b"the user's own figure")
    stray = store / "ab" / "stray.png"
    stray.parent.mkdir(exist_ok=True)
    stray.write_bytes(b"a user file inside the store's folder")
    monkeypatch.setenv("SKINFIT_FIGURE_STORE_MB", "0")
    figure_store.trim()
    left = sorted(p.relative_to(store).as_posix() for p in store.rglob("*") if p.is_file())
    assert left == sorted([figure_store.MARKER, altered.relative_to(store).as_posix(), "ab/stray.png"])
    assert altered.read_bytes() == b"the user's own figure" and not figure_store.fetch(digests[1], tmp_path / "x.png")


def test_class_cache_a_folder_not_the_stores_is_neither_written_nor_trimmed(ea_fit, tmp_path, monkeypatch, drawn):
    """A folder with the store's name that the store did not claim (no marker, other files in
    it): figures are drawn and not stored, the folder is left as it was, and a warning says why."""
    monkeypatch.setenv("SKINFIT_FIGURE_STORE", str(tmp_path / "cache"))
    files = _user_files(tmp_path / "cache" / figure_store.FOLDER)
    monkeypatch.setenv("SKINFIT_FIGURE_STORE_MB", "0")
    with pytest.warns(UserWarning, match="holds files the figure store did not write"):
        _render(ea_fit, tmp_path / "a")
    _render(ea_fit, tmp_path / "b")
    assert drawn == [0, 0], "nothing stored there, so nothing reused"
    figure_store.trim()
    assert _unchanged(files)
    assert not (tmp_path / "cache" / figure_store.FOLDER / figure_store.MARKER).exists()
