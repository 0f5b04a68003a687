"""The static report: parses, is self-contained (no network), shows failures first, and every
table in it holds the saved fits' numbers."""

import json
import math
import os
import re
import sys
import warnings
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import skinfit
from skinfit import plots
from skinfit.apps.cli import main
from skinfit.io.labels import display_unit_map
from skinfit.io.units import pretty_unit, to_si
from skinfit.report import html as report
from skinfit.report.tables import break_at_underscores


class _Page(HTMLParser):
    """Collects every src/href, tables by their data-table/data-id, and the order of things."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.links, self.tags, self.tables, self.order = [], [], {}, []
        self._table = self._row = self._cell = None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.tags.append(tag)
        for key in ("src", "href"):
            if key in attrs:
                self.links.append(attrs[key])
        if tag == "table":
            self._table = {"rows": []}
            self.tables[(attrs.get("data-table"), attrs.get("data-id"))] = self._table
            self.order.append(("table", attrs.get("data-table"), attrs.get("data-id")))
        elif tag == "tr" and self._table is not None:
            self._row = []
        elif tag in ("td", "th") and self._row is not None:
            self._cell = ""
        elif tag == "section":
            self.order.append(("section", attrs.get("id"), None))
        elif tag == "li":
            self.order.append(("li", None, None))

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self._row.append(self._cell.strip())
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self._table["rows"].append(self._row)
            self._row = None
        elif tag == "table":
            self._table = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data
        if self.order and self.order[-1][0] == "li":
            self.order[-1] = ("li", (self.order[-1][1] or "") + data, None)


def _parse(path):
    page = _Page()
    page.feed(Path(path).read_text(encoding="utf-8"))
    page.close()
    return page


def _frame(table):
    header, *rows = table["rows"]
    return pd.DataFrame(rows, columns=header).set_index(header[0])


def _resolution(text):
    """The power of ten of the last digit written in a number's text (``0.0123`` -> -4)."""
    mantissa, _, exponent = text.partition("e")
    decimals = len(mantissa.partition(".")[2])
    return int(exponent or 0) - decimals


def _display_scale(fit, name, column):
    """The factor a summary value of ``name`` is divided by in the page: its display unit's
    factor to SI for its estimates and sd (:func:`skinfit.report.tables.display_units`), else 1."""
    unit = display_unit_map(fit).get(name.split("[")[0])
    estimate = column in ("mean", "sd", "map") or column.startswith("hdi_")
    return to_si(unit) if unit and estimate else 1.0



@pytest.fixture(scope="module")
def rival():
    """A competitor fitted briefly to the same data: it does not converge, and says so (an
    effective sample size of 10^6 cannot come from 300 steps of the ensemble, however well
    the sampler starts)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        return skinfit.fit("electroadhesion_coulomb", "electroadhesion_synthetic", rng=4, max_steps=300,
                           ess_target=1e6, n_global=300)


@pytest.fixture(scope="module")
def written(ea_fit, rival, tmp_path_factory):
    out = tmp_path_factory.mktemp("report") / "ea"
    comparison = pd.DataFrame({"log_z": [512.25, 498.125], "log_z_se": [0.03125, 0.0625],
                               "elpd_loo": [540.5, 522.75], "elpd_loo_se": [10.5, 11.25],
                               "strength": ["best", "decisive for electroadhesion"]},
                              index=pd.Index(["electroadhesion", "electroadhesion_coulomb"], name="model"))
    index = report.write_report([ea_fit, rival], out, title="Electroadhesion: test report", comparison=comparison)
    return index, comparison


def test_report_files_and_self_contained(written):
    index, _ = written
    out = index.parent
    assert index.name == "index.html"
    for name in ["summary.md", "comparison.csv", "electroadhesion__electroadhesion_synthetic_summary.csv",
                 "electroadhesion__electroadhesion_synthetic_diagnostics.csv",
                 "electroadhesion_coulomb__electroadhesion_synthetic_summary.csv"]:
        assert (out / name).stat().st_size > 0, name
    html = index.read_text(encoding="utf-8")
    page = _parse(index)
    assert page.tags[0] == "html" and "body" in page.tags
    assert page.links, "the report links its figures and tables"
    for link in page.links:
        assert not re.match(r"^([a-z][a-z0-9+.-]*:|//)", link, re.I), f"not a relative reference: {link}"
        if not link.startswith("#"):
            assert (out / link).is_file(), f"{link} does not exist beside index.html"
    images = [link for link in page.links if link.endswith(".png")]
    assert len(images) >= 9  # 4 per fit and the comparison chart
    for img in images:
        assert (out / img).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not re.search(r"https?://|ftp://|url\(", html)
    assert "script" not in page.tags and "link" not in page.tags and "iframe" not in page.tags
    anchors = set(re.findall(r'id="([^"]+)"', html))
    for link in page.links:
        if link.startswith("#"):
            assert link[1:] in anchors, link


def test_a_comparison_chart_is_kept_only_while_its_table_is_unchanged(written, ea_fit, rival, tmp_path):
    """The report written again into its folder: the comparison chart is the same file (not
    drawn again) for the same table, and drawn again for a table with another number."""
    import shutil

    index, comparison = written
    out = tmp_path / "again"
    shutil.copytree(index.parent, out)
    chart = out / "figures" / "comparison.png"
    manifest = json.loads((out / "figures" / ".figures.json").read_text())["figures"]
    stamp = chart.stat().st_mtime_ns
    report.write_report([ea_fit, rival], out, title="Electroadhesion: test report", comparison=comparison)
    assert chart.stat().st_mtime_ns == stamp
    assert json.loads((out / "figures" / ".figures.json").read_text())["figures"] == manifest
    changed = comparison.copy()
    changed.loc["electroadhesion_coulomb", "log_z"] = 490.5
    report.write_report([ea_fit, rival], out, title="Electroadhesion: test report", comparison=changed)
    assert chart.stat().st_mtime_ns != stamp
    after = json.loads((out / "figures" / ".figures.json").read_text())["figures"]
    assert after["comparison.png"] != manifest["comparison.png"]
    assert {k: v for k, v in after.items() if k != "comparison.png"} == \
        {k: v for k, v in manifest.items() if k != "comparison.png"}


def test_figures_holds_only_the_figures_its_page_shows(written, ea_fit, monkeypatch, tmp_path):
    """A report into the folder of a report of more fits removes the figures of the fits it no
    longer shows (and the comparison chart it no longer draws), keeps those it shows without
    drawing them again, and never touches a file its manifest does not list or a name outside
    the folder; a figure that fails is removed, never left from the earlier report."""
    import shutil

    index, _ = written
    out = tmp_path / "again"
    shutil.copytree(index.parent, out)
    figdir = out / "figures"
    before = {p.name: p.stat().st_mtime_ns for p in figdir.iterdir() if not p.name.startswith(".")}
    ours = {n for n in before if n.startswith("electroadhesion__")}
    gone = set(before) - ours
    assert any("electroadhesion_coulomb" in n for n in gone) and {"comparison.png", "comparison.pdf"} <= gone
    (figdir / "mine.png").write_bytes(b"the user's own")
    (tmp_path / "outside.png").write_bytes(b"not the report's")
    doc = json.loads((figdir / ".figures.json").read_text())
    record = doc["figures"]["comparison.png"]  # a record the report wrote, listed under names it did not write
    doc["figures"]["../outside.png"] = doc["figures"]["mine.png"] = record
    doc["figures"]["mine.png.png"] = "damaged"
    (figdir / ".figures.json").write_text(json.dumps(doc))
    report.write_report([ea_fit], out, title="one fit")
    left = {p.name: p.stat().st_mtime_ns for p in figdir.iterdir() if not p.name.startswith(".")}
    assert left == {n: before[n] for n in ours} | {"mine.png": left["mine.png"]}
    assert (figdir / "mine.png").read_bytes() == b"the user's own"
    assert set(json.loads((figdir / ".figures.json").read_text())["figures"]) == {n for n in ours if n.endswith(".png")}
    assert (tmp_path / "outside.png").read_bytes() == b"not the report's"
    page = (out / "index.html").read_text()
    assert all(f"figures/{n}" in page for n in ours) and "figures/mine.png" not in page

    def broken(*args, **kwargs):
        raise RuntimeError("no trace today")

    monkeypatch.setattr(plots, "plot_trace", broken)
    report.write_report([ea_fit], out, title="one fit")
    trace = "electroadhesion__electroadhesion_synthetic_trace"
    assert not (figdir / f"{trace}.png").exists() and not (figdir / f"{trace}.pdf").exists()
    assert f"figure {trace}.png could not be drawn (RuntimeError: no trace today)" in (out / "index.html").read_text()


def test_analyses_given_to_a_report_run_while_its_figures_are_drawn(written, ea_fit, rival, tmp_path, monkeypatch):
    """``write_report(analyses=...)``: called once, while the figure workers draw (they are
    alive when it runs), and its comparison is the one the page shows and charts; a key the
    report does not take is refused."""
    import multiprocessing

    from skinfit.inference.workers import forkable

    _, comparison = written
    calls = []

    def analyses():
        calls.append([p.name for p in multiprocessing.active_children()])
        return {"comparison": comparison}

    out = tmp_path / "hooked"
    fork = forkable()  # asked before: while the workers draw, their pool's thread runs here
    report.write_report([ea_fit, rival], out, title="hooked", analyses=analyses)
    # figure workers are forked only from a process without other threads (an earlier test's Dask
    # client leaves its threads here); otherwise the figures are drawn after, in this process
    assert len(calls) == 1 and bool(calls[0]) == fork, (fork, calls)
    assert pd.read_csv(out / "comparison.csv", index_col=0).loc["electroadhesion", "log_z"] == 512.25
    assert "figures/comparison.png" in (out / "index.html").read_text()
    assert (out / "figures" / "comparison.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    refused = tmp_path / "refused"
    with pytest.raises(TypeError, match="analyses.. returned contrast"):
        report.write_report([ea_fit], refused, analyses=lambda: {"contrast": {}})
    assert not (refused / "index.html").exists()
    if fork:  # figures drawn by workers meanwhile are recorded, and the next report into the folder reuses them
        drawn = set(json.loads((refused / "figures" / ".figures.json").read_text())["figures"])
        assert drawn and all((refused / "figures" / n).exists() for n in drawn)
        stamps = {n: (refused / "figures" / n).stat().st_mtime_ns for n in drawn}
        report.write_report([ea_fit], refused)
        assert {n: (refused / "figures" / n).stat().st_mtime_ns for n in drawn} == stamps


@pytest.mark.parametrize("fork", [True, False])
def test_analyses_run_once_when_no_worker_draws_meanwhile(written, ea_fit, rival, tmp_path, monkeypatch, fork):
    """Every fit's figure already in the folder (or no fork, as on macOS and Windows): the
    analyses still run once, and the comparison chart of the table they return is drawn."""
    import multiprocessing
    import shutil

    index, comparison = written
    out = tmp_path / "again"
    shutil.copytree(index.parent, out)
    if not fork:
        monkeypatch.setattr(multiprocessing, "get_all_start_methods", lambda: ["spawn"])
    changed = comparison.copy()
    changed.loc["electroadhesion_coulomb", "log_z"] = 490.5
    chart = out / "figures" / "comparison.png"
    stamp, calls = chart.stat().st_mtime_ns, []
    report.write_report([ea_fit, rival], out, title="again",
                        analyses=lambda: calls.append(1) or {"comparison": changed})
    assert calls == [1] and chart.stat().st_mtime_ns != stamp
    assert pd.read_csv(out / "comparison.csv", index_col=0).loc["electroadhesion_coulomb", "log_z"] == 490.5


def test_failures_are_at_the_top(written, rival):
    index, _ = written
    page = _parse(index)
    assert not rival.converged
    first_table = next(i for i, o in enumerate(page.order) if o[0] == "table")
    failures = [i for i, o in enumerate(page.order) if o[0] == "li" and o[1] and "FAIL" in o[1]
                and "electroadhesion_coulomb" in o[1] and "not converged" in o[1]]
    assert failures and failures[0] < first_table
    assert page.order[0] == ("section", "diagnostics", None)
    md = (index.parent / "summary.md").read_text()
    assert md.index("**FAIL** electroadhesion_coulomb") < md.index("### Posterior summary")


def test_tables_hold_the_saved_numbers(written, ea_fit, rival):
    index, comparison = written
    out = index.parent
    page = _parse(index)
    md = (out / "summary.md").read_text()
    for fit, key in [(ea_fit, "electroadhesion__electroadhesion_synthetic"),
                     (rival, "electroadhesion_coulomb__electroadhesion_synthetic")]:
        summary = fit.summary()
        shown = _frame(page.tables["summary", key])
        assert list(shown.index) == list(summary.index)
        for col in summary.columns:
            for name in summary.index:
                want, got = summary.loc[name, col], shown.loc[name, col]
                if col == "unit":  # in its display unit, written as a physicist writes it: checked below
                    continue
                if isinstance(want, str):
                    assert got == want
                elif math.isnan(want):  # n/a where no value exists by construction (a derived quantity's MAP...)
                    derived = str(summary.loc[name, "note"]).startswith("derived")
                    assert got == ("n/a" if derived and col in ("map", "tau", "contraction") else "nan"), (name, col)
                else:  # at the precision its sd allows (tests/test_report_numbers.py), in its display unit
                    scale = _display_scale(fit, name, col)
                    assert abs(float(got) - want / scale) <= 0.5 * 10 ** _resolution(got) * (1 + 1e-9), \
                        (key, name, col, got, want)
                    assert f"| {got} |" in md or f"| {got} " in md
        units = plots.parameter_units(fit)
        display = display_unit_map(fit)
        assert list(shown["unit"]) == [re.sub("<[^>]+>", "", pretty_unit(display.get(n.split("[")[0],
                                                                                  units[n.split("[")[0]]), html=True))
                                       for n in summary.index]
        # the CSV is the summary itself, to the last bit
        csv = pd.read_csv(out / f"{key}_summary.csv", index_col=0, keep_default_na=False)
        numeric = [c for c in summary.columns if c not in ("note", "unit")]
        np.testing.assert_array_equal(csv[numeric].to_numpy(dtype=float), summary[numeric].to_numpy(dtype=float))
        assert list(csv["note"]) == list(summary["note"])
        # diagnostics: the sampler's own record
        diag = _frame(page.tables["diagnostics", key])
        sampler = fit.attr("sampler")
        assert diag.loc["converged", "value"] == ("yes" if fit.converged else "no")
        assert diag.loc["converged", "status"] == ("ok" if fit.converged else "FAIL")
        assert float(diag.loc["acceptance mean", "value"]) == pytest.approx(sampler["acceptance_mean"], rel=1e-3)
        assert int(diag.loc["steps", "value"]) == sampler["n_steps"]
        assert int(diag.loc["evaluations outside the physical support", "value"]) == \
            fit.attr("support_counts")["outside_support"]
        assert float(diag.loc["min ESS bulk", "value"]) == pytest.approx(summary["ess_bulk"].min(), abs=0.5)
        csv_diag = pd.read_csv(out / f"{key}_diagnostics.csv", index_col=0, keep_default_na=False)
        assert list(csv_diag.index) == list(diag.index)
        assert list(csv_diag["status"]) == list(diag["status"])
    cmp_shown = _frame(page.tables["comparison", "comparison.csv"])
    assert list(cmp_shown.index) == list(comparison.index)
    for col in comparison.columns:
        for got, want in zip(cmp_shown[col], comparison[col]):
            if isinstance(want, str):
                assert got == want
            else:
                assert abs(float(got) - want) <= 0.5 * 10 ** _resolution(got) * (1 + 1e-9), (col, got, want)
    pd.testing.assert_frame_equal(pd.read_csv(out / "comparison.csv", index_col=0), comparison)


def test_each_section_names_what_produced_it(written, ea_fit, rival):
    index, _ = written
    html = index.read_text(encoding="utf-8")
    sections = re.split(r'<section id="', html)
    for fit in (ea_fit, rival):
        key = f"{fit.model_id}__{fit.dataset_id}"
        (section,) = [s for s in sections if s.startswith(key + '"')]
        attrs = fit.idata.attrs
        version = fit.attr("versions")["skinfit"]
        for needle in [attrs["model_id"], attrs["model_sha256"][:12], attrs["priors_id"], attrs["priors_sha256"][:12],
                       attrs["dataset_id"], attrs["dataset_sha256"][:12], f"skinfit {version}", "simulated"]:
            assert needle in section, (key, needle)


def test_cli_report_from_run_directories(rival, tmp_path, capsys):
    rival.save(tmp_path / "runs" / "S01" / "fit.nc")
    rival.save(tmp_path / "runs" / "S02" / "fit.nc")
    assert main(["report", str(tmp_path / "runs"), "--out", str(tmp_path / "rep")]) == 0
    assert "report written" in capsys.readouterr().out
    page = _parse(tmp_path / "rep" / "index.html")
    # one fit saved twice: two sections, told apart by their files (skinfit.results.run_labels)
    summaries = sorted(key for kind, key in page.tables if kind == "summary")
    assert len(summaries) == 2 and "file_S01_fit.nc" in summaries[0] and "file_S02_fit.nc" in summaries[1]
    # two fits of one model: one figure of forest plots across them, every parameter side by side
    assert any(link.endswith("across_electroadhesion_coulomb.png") for link in page.links)
    assert main(["report", str(tmp_path / "nothing"), "--out", str(tmp_path / "rep2")]) == 2
    assert "no such run directory" in capsys.readouterr().err


def test_a_report_with_nothing_to_draw_reads_the_stored_summary(ea_fit, tmp_path, monkeypatch):
    """``skinfit report`` of a saved fit into a folder that holds its figures: the summary is
    read from the fit file (never computed again); every table equals the
    first report's, whose summary was computed (the file had none stored then)."""
    import shutil

    import xarray as xr

    from skinfit.results.fit import Fit

    run = tmp_path / "run"
    path = ea_fit.save(run / "fit.nc")
    tree = xr.open_datatree(path).load()
    del tree.attrs["summary"]
    from skinfit.io import integrity

    integrity.stamp(tree)  # the file without a stored summary, with the checksums of its content
    tree.to_netcdf(tmp_path / "bare.nc", engine="h5netcdf")
    os.replace(tmp_path / "bare.nc", path)
    assert not skinfit.load_fit(path).summary_stored
    first, again = tmp_path / "first", tmp_path / "again"
    assert main(["report", str(run), "--out", str(first)]) == 0  # the summary computed, the figures drawn
    shutil.copytree(first, again)
    ea_fit.save(path)
    assert skinfit.load_fit(path).summary_stored

    def computed(self):
        raise AssertionError("the summary was computed again, not read from the file")

    monkeypatch.setattr(Fit, "_compute_summary", computed)
    assert main(["report", str(run), "--out", str(again)]) == 0
    written = sorted(p.name for p in first.iterdir() if p.is_file())
    assert "summary.md" in written and any(n.endswith("_summary.csv") for n in written)
    for name in written:
        assert (again / name).read_bytes() == (first / name).read_bytes(), name


_KILLED_REPORT = """
import os, sys, time
from pathlib import Path
from skinfit import plots
from skinfit.report import html as report
from skinfit.results.fit import load_fit

os.cpu_count = lambda: 2  # two figure workers even on a one-core machine

def stuck(fit, *args, **kwargs):  # a figure that takes far longer than the test waits
    Path(sys.argv[2], f"worker-{os.getpid()}").write_text("")
    time.sleep(120)

plots.plot_ppc = plots.plot_trace = stuck
report.write_report(load_fit(sys.argv[1]), sys.argv[3])
"""


def _alive(pid):
    """Running (a zombie left unreaped by an init that does not reap counts as ended)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ("Z", "X")


@pytest.mark.skipif(not Path("/proc").is_dir() or "fork" not in __import__("multiprocessing").get_all_start_methods(),
                    reason="needs fork and /proc (Linux) to find the figure workers")
def test_figure_workers_end_when_the_report_process_is_killed(ea_fit, tmp_path):
    """kill -9 of a report process mid-drawing: its forked figure workers end within seconds
    rather than drawing on as orphans."""
    import signal
    import subprocess
    import time

    ea_fit.save(tmp_path / "fit.nc")
    marks = tmp_path / "marks"
    marks.mkdir()
    proc = subprocess.Popen([sys.executable, "-c", _KILLED_REPORT, str(tmp_path / "fit.nc"), str(marks),
                             str(tmp_path / "report")])
    deadline = time.monotonic() + 120
    while len(list(marks.iterdir())) < 2 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    workers = [int(p.name.split("-")[1]) for p in marks.iterdir()]
    assert len(workers) == 2, f"two workers should be drawing (report exited {proc.poll()})"
    assert all(_alive(pid) for pid in workers)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    deadline = time.monotonic() + 5
    while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    survivors = [pid for pid in workers if _alive(pid)]
    for pid in survivors:  # leave nothing behind, then fail
        os.kill(pid, signal.SIGKILL)
    assert not survivors, f"figure workers {survivors} outlived their report process"


def test_table_names_break_at_their_underscores_and_stay_escaped(written):
    """A table cell gets a line-break opportunity after each underscore, so a narrow column
    breaks ``electroadhesion_coulomb`` between its words (the cell's text is unchanged for a
    reader or a parser), and the text is still escaped: a name cannot inject markup."""
    index, _ = written
    html = index.read_text(encoding="utf-8")
    assert '<td class="text">electroadhesion_<wbr>coulomb</td>' in html
    assert ">log_<wbr>z_<wbr>se</th>" in html
    assert "electroadhesion_coulomb" in _frame(_parse(index).tables[("comparison", "comparison.csv")]).index
    assert str(break_at_underscores("a<b>_c&d")) == "a&lt;b&gt;_<wbr>c&amp;d"


def test_a_report_never_overwrites_a_folder_of_the_users_files(ea_fit, tmp_path, no_figures, capsys):
    """`--out` naming a folder of the user's own files (index.html, summary.md, a CSV): refused
    with one line naming it, and not a byte changed or added; a folder an earlier report wrote
    (its marker, or a skinfit index.html from before the marker) is written again."""
    run = tmp_path / "run"
    ea_fit.save(run / "fit.nc")
    mine = tmp_path / "site"
    mine.mkdir()
    files = {"index.html": b"<html>my lab page</html>", "summary.md": b"my notes", "data_summary.csv": b"a,b\n1,2\n"}
    for name, data in files.items():
        (mine / name).write_bytes(data)
    capsys.readouterr()
    assert main(["report", str(run), "--out", str(mine)]) != 0
    err = capsys.readouterr().err.strip()
    assert err == (f"skinfit: error: {mine}: holds files a skinfit report did not write: give a new or empty "
                   f"folder, e.g. {mine / 'report'} (nothing was written)")
    assert {p.name: p.read_bytes() for p in mine.iterdir()} == files
    (tmp_path / "a_file").write_text("x")
    assert main(["report", str(run), "--out", str(tmp_path / "a_file")]) != 0
    assert capsys.readouterr().err.strip() == (f"skinfit: error: {tmp_path / 'a_file'}: is a file: --out names the "
                                               "folder the report is written into")
    assert (tmp_path / "a_file").read_text() == "x"

    new = tmp_path / "new"
    assert main(["report", str(run), "--out", str(new)]) == 0
    assert (new / report.REPORT_MARKER).exists()
    assert main(["report", str(run), "--out", str(new)]) == 0  # its own folder: written again
    (new / report.REPORT_MARKER).unlink()  # a report folder from before the marker: its index.html says skinfit
    assert main(["report", str(run), "--out", str(new)]) == 0 and (new / report.REPORT_MARKER).exists()


def test_a_report_into_its_folder_again_leaves_no_stale_table_and_waits_for_no_one(ea_fit, tmp_path, no_figures):
    """The second report into a folder removes the tables and pages the first wrote that it does
    not write (a fit no longer reported), keeps a file the user put there, and a report while
    another holds the folder is refused with one line."""
    import os

    from skinfit.inference.checkpoint import CheckpointLock

    coulomb = skinfit.fit("electroadhesion_coulomb", "electroadhesion_synthetic", rng=2, max_steps=300,
                          ess_target=50)
    out = tmp_path / "r"
    report.write_report({"ea": ea_fit, "coulomb": coulomb}, out)
    assert (out / "coulomb_summary.csv").exists() and (out / "ea_summary.csv").exists()
    (out / "notes.txt").write_text("mine")
    report.write_report({"ea": ea_fit}, out)
    tables = sorted(p.name for p in out.glob("*.csv"))
    assert tables == ["ea_diagnostics.csv", "ea_summary.csv"]
    assert (out / "notes.txt").read_text() == "mine" and "coulomb_summary.csv" not in (out / "index.html").read_text()
    assert sorted(json.loads((out / report.REPORT_MARKER).read_text())["files"]) == \
        ["ea_diagnostics.csv", "ea_summary.csv", "index.html", "summary.md"]

    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and p.suffix != ".lock"}
    with CheckpointLock(out / "report"):  # another report writing into it
        with pytest.raises(skinfit.InputError, match=f"is in use by pid {os.getpid()}"):
            report.write_report({"ea": ea_fit}, out)
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and p.suffix != ".lock"} == before


def test_a_report_of_a_run_reports_the_fits_its_index_lists(ea_fit, tmp_path, no_figures, capsys):
    """`skinfit report RUN` of a run with an index.json (a --by run, a campaign): the fits it
    lists, and a word on a fit file below RUN that it does not list (another run's, left there)
    instead of reporting it as if it were one of the run's; a listed file missing is an error."""
    run = tmp_path / "run"
    ea_fit.save(run / "a" / "fit.nc")
    (run / "index.json").write_text(json.dumps({"model": "electroadhesion", "groups": [{"group": "g=a",
                                                                                      "path": "a/fit.nc"}]}))
    coulomb = skinfit.fit("electroadhesion_coulomb", "electroadhesion_synthetic", rng=2, max_steps=300,
                          ess_target=50)
    coulomb.save(run / "left" / "over" / "fit.nc")
    capsys.readouterr()
    assert main(["report", str(run), "--out", str(tmp_path / "r"), "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out[out.index("{"):])["fits"] == ["electroadhesion__electroadhesion_synthetic"]
    assert (f"skinfit report: warning: 1 fit file(s) below {run} are not in its index.json (e.g. "
            f"{run / 'left' / 'over' / 'fit.nc'}): not reported") in err
    # a campaign's index: done fits only, the failed one named
    (run / "index.json").write_text(json.dumps([{"status": "complete", "path": "a/fit.nc"},
                                                {"status": "failed: ValueError: x", "path": "b/fit.nc"}]))
    assert main(["report", str(run), "--out", str(tmp_path / "r"), "--json"]) == 0
    assert (f"skinfit report: 1 fit(s) of {run / 'index.json'} not complete (failed or pending): not reported"
            in capsys.readouterr().err)
    (run / "index.json").write_text(json.dumps({"groups": [{"group": "g=a", "path": "gone/fit.nc"}]}))
    assert main(["report", str(run), "--out", str(tmp_path / "r")]) == 2
    assert "lists gone/fit.nc, which does not exist" in capsys.readouterr().err


def test_fork_from_a_threaded_process_never_happens_figures_drawn_here(ea_fit, tmp_path, monkeypatch):
    """A report written from a process that runs other threads (a notebook kernel, a Dask
    client): forking it could deadlock a figure worker on a lock another thread held, and Python
    warns ("This process ... is multi-threaded, use of fork() may lead to deadlocks"). The
    figures are drawn in this process instead: no such warning, every figure drawn. (The
    warning is recorded, not raised: CPython clears an error raised by it, so -W error hides it.)"""
    import threading

    monkeypatch.setattr(os, "cpu_count", lambda: 2)  # two figure workers, were fork allowed
    stop = threading.Event()
    other = threading.Thread(target=stop.wait, daemon=True)
    other.start()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            index = report.write_report(ea_fit, tmp_path / "r")
    finally:
        stop.set()
        other.join()
    assert not [w for w in caught if "use of fork()" in str(w.message)], [str(w.message) for w in caught]
    assert "could not be drawn" not in index.read_text()
    assert len(list((tmp_path / "r" / "figures").glob("*.png"))) == 4  # the fit's four figures
