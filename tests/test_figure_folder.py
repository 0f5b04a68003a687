"""A report folder keeps the figures it drew while what they are drawn from is unchanged
(:class:`skinfit.report.figure_folder.FigureFolder`): a figure is drawn again for other fit
content, another plot function, or a damaged or edited file, and nothing is written outside
the report folder. (That a user's files in the folder survive: tests/test_own_files.py.)"""

import hashlib
import json
from pathlib import Path

import pytest

from skinfit import plots
from skinfit.report import figures
from skinfit.report.figure_folder import MANIFEST
from skinfit.results.fit import load_fit


@pytest.fixture
def drawn(monkeypatch):
    """The indices of the figure jobs drawn (one worker: drawn in this process)."""
    calls = []
    original = figures.render_one
    monkeypatch.setattr(figures, "MAX_FIGURE_WORKERS", 1)
    monkeypatch.setattr(figures, "render_one", lambda i: calls.append(i) or original(i))
    return calls


def _render(fit, folder, func="plot_prior_posterior"):
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"fit_{func}.png"
    errors = figures.render_figures([fit], [{"fit": 0, "func": func, "args": (), "path": path}], folder)
    assert errors == [None]
    return path


def _digests(path):
    return {s: hashlib.sha256(Path(path).with_suffix(s).read_bytes()).hexdigest() for s in (".png", ".pdf")}


def test_an_unchanged_figure_is_kept_a_changed_fit_redraws_it(ea_fit, drawn, tmp_path):
    first = _render(ea_fit, tmp_path / "a")
    files = _digests(first)
    stamp = first.stat().st_mtime_ns
    assert drawn == [0]
    _render(ea_fit, tmp_path / "a")
    assert drawn == [0], "the same fit's figure in the same folder is kept, not drawn again"
    assert first.stat().st_mtime_ns == stamp and _digests(first) == files

    ea_fit.save(tmp_path / "fit.nc")
    other = load_fit(tmp_path / "fit.nc")
    name = next(iter(other.group("posterior").data_vars))
    other.idata["posterior"][name].values[0, 0] *= 1.5  # one draw of one walker changed
    _render(other, tmp_path / "a")
    assert drawn == [0, 0], "other content is drawn again"


@pytest.mark.parametrize("suffix", [".png", ".pdf"])
@pytest.mark.parametrize("damage", ["truncated", "edited", "deleted"])
def test_a_damaged_or_edited_figure_is_drawn_again(ea_fit, drawn, tmp_path, suffix, damage):
    path = _render(ea_fit, tmp_path / "a")
    files = _digests(path)
    target = path.with_suffix(suffix)
    if damage == "truncated":
        target.write_bytes(target.read_bytes()[:-10])
    elif damage == "edited":  # same size, one byte changed
        data = bytearray(target.read_bytes())
        data[len(data) // 2] ^= 0xFF
        target.write_bytes(bytes(data))
    else:
        target.unlink()
    _render(ea_fit, tmp_path / "a")
    assert drawn == [0, 0]
    assert _digests(path) == files, "drawn whole again: the same bytes as first drawn"


def test_a_replaced_plot_function_draws_again(ea_fit, drawn, tmp_path, monkeypatch):
    _render(ea_fit, tmp_path / "a")
    original = plots.plot_prior_posterior
    monkeypatch.setattr(plots, "plot_prior_posterior", lambda fit, *a, **k: original(fit, *a, **k))
    _render(ea_fit, tmp_path / "a")
    assert drawn == [0, 0]


def test_a_record_not_the_reports_is_empty(ea_fit, drawn, tmp_path):
    """A record the report did not write (an older skinfit's, a damaged one): every figure drawn
    again, none taken for unchanged."""
    path = _render(ea_fit, tmp_path / "a")
    record = tmp_path / "a" / MANIFEST
    for text in ("{not json", json.dumps({path.name: "a key"}), json.dumps({"figures": {path.name: {}}})):
        record.write_text(text)
        _render(ea_fit, tmp_path / "a")
    assert drawn == [0, 0, 0, 0]


def test_nothing_is_written_outside_the_report_folder(ea_fit, drawn, tmp_path, monkeypatch):
    """Each report folder draws its own figures: none is kept in, or copied from, a folder
    shared between reports (the user's cache folder)."""
    cache = tmp_path / "cache"
    monkeypatch.setenv("XDG_CACHE_HOME", str(cache))
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    a, b = _render(ea_fit, tmp_path / "a"), _render(ea_fit, tmp_path / "b")
    assert drawn == [0, 0] and _digests(a) == _digests(b)
    written = [p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file()]
    # skinfit.plots keeps the figures' font in the cache folder; the report writes nothing there
    assert sorted(n for n in written if not n.startswith("cache/skinfit/fonts/")) == sorted(
        f"{d}/{n}" for d in "ab" for n in (a.name, a.with_suffix(".pdf").name, MANIFEST))


def test_contrast_matrices_are_kept_while_their_pairs_are_the_same(ea_fit, drawn, tmp_path):
    """A report's contrast matrices are figure jobs like the others: a second report into the
    same folder draws none of them again; another contrast table draws its matrix again."""
    import itertools

    import numpy as np
    import pandas as pd

    from skinfit.analysis.contrasts import contrast
    from skinfit.report.html import MATRIX_LABELS, write_report

    rng = np.random.default_rng(0)
    subjects = {f"S{i:02d}": np.exp(rng.normal(np.log(2e4) + 0.1 * i, 0.1, 2000)) for i in range(MATRIX_LABELS)}

    def table(shift=1.0):
        return pd.DataFrame([{"A": a, "B": b, "parameter": "E_star", **contrast(subjects[a] * shift, subjects[b])}
                             for a, b in itertools.combinations(subjects, 2)])

    out = tmp_path / "report"
    write_report({"ea": ea_fit}, out, contrasts={"between subjects": table()})
    matrix = out / "figures" / "contrasts_between_subjects_E_star.png"
    first, stamp = len(drawn), matrix.stat().st_mtime_ns
    assert first >= 2 and 'src="figures/contrasts_between_subjects_E_star.png"' in (out / "index.html").read_text()
    write_report({"ea": ea_fit}, out, contrasts={"between subjects": table()})
    assert len(drawn) == first and matrix.stat().st_mtime_ns == stamp, "unchanged: nothing drawn again"
    write_report({"ea": ea_fit}, out, contrasts={"between subjects": table(shift=1.2)})
    assert len(drawn) == first + 1 and matrix.stat().st_mtime_ns != stamp, "other pairs: the matrix drawn again"


def test_the_figure_and_cache_keys_cover_every_layer_of_the_source():
    """A report's kept figures and the population cache are keyed by skinfit's source
    (io.paths.code_hash): every layer's files are in it, the plots and the report included, so
    that a changed plot or analysis never reuses what older code made (it once hashed io/ alone)."""
    from skinfit.io.paths import source_files

    root = Path(figures.__file__).parents[1]
    folders = {p.relative_to(root).parts[0] for p in source_files() if len(p.relative_to(root).parts) > 1}
    assert {"physics", "io", "inference", "results", "analysis", "plots", "report", "apps"} <= folders
    names = {p.relative_to(root).as_posix() for p in source_files()}
    assert {"posterior.py", "plots/pair.py", "report/templates/report.html.j2", "physics/electroadhesion.py"} <= names


def test_a_changed_plot_module_changes_the_source_hash(monkeypatch):
    """One byte more in skinfit/plots/pair.py, as read by the hash, gives another source hash:
    the figures it drew are not kept for the changed code."""
    from skinfit.io import paths

    before = paths.source_hash.__wrapped__()
    pair = Path(figures.__file__).parents[1] / "plots" / "pair.py"
    read = Path.read_bytes
    monkeypatch.setattr(Path, "read_bytes", lambda self: read(self) + (b"#" if self == pair else b""))
    assert paths.source_hash.__wrapped__() != before
    monkeypatch.undo()
    assert paths.source_hash.__wrapped__() == before  # the same files, the same hash
