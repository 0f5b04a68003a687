"""A report a reader can use: every number of its HTML tables at the precision its posterior sd
allows, one interval probability in the whole page, units written as a physicist writes them,
and ``Fit.summary`` equal to ArviZ's own summary at the same interval setting.

The report is written from short fits (seconds) without its figures (``no_figures``): these
tests read the tables and the text, not the images."""

import math
import re
import sys
import warnings
from html.parser import HTMLParser
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest

import skinfit
from skinfit import plots
from skinfit.io.labels import round_to_sd, sd_resolution
from skinfit.io.units import pretty_unit
from skinfit.report import html as report
from skinfit.report.figures import job_keys
from skinfit.results.intervals import hdi, interval_columns


class _Tables(HTMLParser):
    """Every table of a page as a list of rows of cell texts (header first)."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.tables, self._row, self._cell = [], None, None

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append({"kind": dict(attrs).get("data-table"), "rows": []})
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th"):
            self._cell = ""

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self._row.append(self._cell.strip())
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self.tables[-1]["rows"].append(self._row)
            self._row = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data


def _markdown_tables(text):
    """The tables of a Markdown text as lists of rows of cell texts (header first)."""
    tables, current = [], None
    for line in text.splitlines():
        if line.startswith("|"):
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]]
            if set("".join(cells)) <= set("-"):
                continue
            if current is None:
                current = []
                tables.append(current)
            current.append(cells)
        else:
            current = None
    return tables


def _tables(path):
    page = _Tables()
    page.feed(Path(path).read_text(encoding="utf-8"))
    return page.tables


_NUMBER = re.compile(r"[-−]?(\d+)(?:\.(\d+))?(?:e([-+]\d+))?")
_ESTIMATE = re.compile(r"^(mean|median|map|estimate|lower|upper|separate|shrunk)$|^(hdi_|separate_|shrunk_)")


def resolution(text):
    """The power of ten of the last significant digit of a number written as ``text`` (trailing
    zeros of an integer are not significant: ``12300`` -> 2), or None for a cell not a number."""
    m = _NUMBER.fullmatch(text)
    if not m:
        return None
    whole, decimals, exponent = m.groups()
    e = int(exponent or 0)
    if decimals:
        return e - len(decimals)
    stripped = whole.rstrip("0")
    return e + (len(whole) - len(stripped) if stripped else 0)


def significant_digits(text):
    m = _NUMBER.fullmatch(text)
    digits = (m.group(1) + (m.group(2) or "")).lstrip("0")
    return len(digits) if m.group(2) else len(digits.rstrip("0"))


def too_precise(table):
    """'row, column: cell (sd)' for each estimate or interval end of a table of cell texts
    written with more digits than the sd of its row allows (the sd's own last digit is the
    place of its second significant digit), and each sd with more than two significant digits."""
    header, *rows = table
    bad = []
    if "sd" not in header:
        return bad
    j_sd = header.index("sd")
    for row in rows:
        sd = row[j_sd]
        if resolution(sd) is None:
            continue
        if significant_digits(sd) > 2:
            bad.append(f"{row[0]}, sd: {sd} (more than two significant digits)")
        for j, column in enumerate(header):
            if j and _ESTIMATE.search(column) and resolution(row[j]) is not None and resolution(row[j]) < resolution(sd):
                bad.append(f"{row[0]}, {column}: {row[j]} (sd {sd})")
    return bad


def interval_probabilities(text):
    """The interval probabilities a page names: ``94% HDI``, ``95% interval``, columns ``hdi_3%``."""
    named = {float(p) for p in re.findall(r"(\d+(?:\.\d+)?)% (?:HDI|ETI|interval|credible|CI)", text)}
    for lo, hi in re.findall(r"hdi_(\d+(?:\.\d+)?)%.*?hdi_(\d+(?:\.\d+)?)%", text):
        named.add(round(float(hi) - float(lo), 6))
    return named


def ascii_units(tables):
    """Unit cells written in ASCII exponent or product notation (``N*s/m``, ``m^2``)."""
    bad = []
    for t in tables:
        header, *rows = t["rows"]
        if "unit" in header:
            j = header.index("unit")
            bad += [row[j] for row in rows if re.search(r"[*^]", row[j])]
    return bad


@pytest.fixture(scope="module")
def short_fits():
    """A short electroadhesion fit, and one with alpha split by voltage (its levels give a
    contrast table): a few seconds each."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = skinfit.fit("electroadhesion", "electroadhesion_synthetic", rng=1, max_steps=400, n_global=100,
                            progress=False)
        split = skinfit.fit("electroadhesion", "electroadhesion_synthetic", rng=2, max_steps=400, n_global=100,
                            split={"alpha": ["voltage"]}, progress=False)
    return plain, split


def _write(fits, out, **kwargs):
    plain, split = fits
    _, contrasts = report.group_analyses({"plain": plain, "split": split}, ci_prob=kwargs.get("ci_prob"))
    return report.write_report({"plain": plain, "split": split}, out, contrasts=contrasts, **kwargs)


@pytest.fixture(scope="module")
def written(short_fits, tmp_path_factory):
    import skinfit.report.html as module

    original = module.render_figures
    module.render_figures = lambda fits, jobs, figdir, workers=None, meanwhile=None: [None] * (
        len(jobs) + len(meanwhile() if meanwhile is not None else []))
    try:
        yield _write(short_fits, tmp_path_factory.mktemp("numbers") / "report")
    finally:
        module.render_figures = original


def test_round_to_sd_keeps_the_second_significant_digit_of_the_sd():
    assert round_to_sd(2.409213, 0.0123) == "2.409"
    assert round_to_sd(0.0123, 0.0123) == "0.012"
    assert round_to_sd(2.40921e-7, 1.23e-8) == "2.41e-07"
    assert round_to_sd(12345.6, 230) == "12350"
    assert round_to_sd(0.00041, 0.0123) == "0.000"  # zero at the resolution, its decimals shown
    assert round_to_sd(1.5, float("nan")) == "1.5"
    assert sd_resolution(0.0123) == -3 and sd_resolution(0.0) is None


def test_the_checkers_catch_what_they_look_for():
    """Negative controls: a table at six significant digits, two interval conventions and
    ASCII units are each found."""
    table = [["parameter", "mean", "sd", "hdi_3%"], ["E", "2.40921e-07", "1.2e-08", "2.1e-07"]]
    assert too_precise(table) == ["E, mean: 2.40921e-07 (sd 1.2e-08)"]
    assert too_precise([["p", "mean", "sd"], ["a", "6751", "6751.15"]]) == ["a, sd: 6751.15 (more than two "
                                                                            "significant digits)"]
    assert too_precise([["p", "mean", "sd"], ["a", "12300", "1200"]]) == []
    assert interval_probabilities("a 94% HDI here, a 95% interval there") == {94.0, 95.0}
    assert interval_probabilities("<th>hdi_5%</th><th>hdi_95%</th>") == {90.0}
    assert ascii_units([{"rows": [["p", "unit"], ["eta", "m^2/N^2"], ["c", "N*s/m"], ["E", "kPa"]]}]) == \
        ["m^2/N^2", "N*s/m"]


def test_every_number_at_the_precision_its_sd_allows(written):
    tables = _tables(written)
    kinds = {t["kind"] for t in tables}
    assert {"summary", "contrasts"} <= kinds
    checked = 0
    for t in tables:
        assert too_precise(t["rows"]) == [], t["kind"]
        checked += "sd" in t["rows"][0]
        header, *rows = t["rows"]
        for j, column in enumerate(header):
            cells = [r[j] for r in rows if r[j] not in ("n/a", "nan", "")]
            if column == "r_hat":
                assert all(re.fullmatch(r"\d\.\d\d", c) for c in cells), cells
            elif column.startswith("ess_"):
                assert all(re.fullmatch(r"\d+", c) for c in cells), cells
    assert checked >= 2  # the summaries and the contrasts
    md = _markdown_tables((written.parent / "summary.md").read_text(encoding="utf-8"))
    assert sum("sd" in t[0] for t in md) >= 2
    assert [bad for t in md for bad in too_precise(t)] == []  # summary.md: the same rounding


def test_one_interval_probability_named_in_the_whole_report(written):
    text = written.read_text(encoding="utf-8")
    assert interval_probabilities(text) == {94.0}
    assert "94% HDI" in text
    assert interval_probabilities((written.parent / "summary.md").read_text(encoding="utf-8")) == {94.0}


def _jobs_of(fits, out, monkeypatch, **kwargs):
    """The figure jobs a report hands to render_figures (nothing drawn), and its index."""
    seen = []

    def drawn(fits, jobs, figdir, workers=None, meanwhile=None):
        seen.extend(jobs)
        seen.extend(meanwhile() if meanwhile is not None else [])
        return [None] * len(seen)

    monkeypatch.setattr(report, "render_figures", drawn)
    return _write(fits, out, **kwargs), seen


def test_ci_option_changes_every_interval_and_is_recorded(short_fits, tmp_path, monkeypatch):
    """Every table, its text and every figure's caption at 90%; the forest of the split
    parameter draws the 90% HDI of the draws, and its figure's key changes with the setting (a
    report at 0.9 into a folder drawn at 0.94 draws it again)."""
    index, jobs = _jobs_of(short_fits, tmp_path / "ci90", monkeypatch, ci_prob=0.9)
    text = index.read_text(encoding="utf-8")
    assert interval_probabilities(text) == {90.0} and 'data-ci="0.9"' in text and "94%" not in text
    summary = next(t for t in _tables(index) if t["kind"] == "summary")["rows"][0]
    assert list(interval_columns(0.9)) == ["hdi_5%", "hdi_95%"] and "hdi_5%" in summary
    forests = [j for j in jobs if j["func"] == "plot_forest"]
    assert forests and all(j["kwargs"]["ci_prob"] == 0.9 for j in forests)
    assert all("90% HDI" in j["entry"]["caption"] for j in forests)
    _, jobs94 = _jobs_of(short_fits, tmp_path / "ci94", monkeypatch)
    fits = list(short_fits)
    keys = dict(zip((j["path"].name for j in jobs), job_keys(fits, jobs)))
    keys94 = dict(zip((j["path"].name for j in jobs94), job_keys(fits, jobs94)))
    assert all(keys[j["path"].name] != keys94[j["path"].name] for j in forests)

    split = short_fits[1]
    job = next(j for j in forests if j["fit"] == 1)
    fig = plots.plot_forest(split, *job["args"], **job["kwargs"])
    try:
        assert job["args"] == (["alpha"],)
        draws = split.group("posterior")["alpha"]
        level_dim = next(d for d in draws.dims if d not in ("chain", "draw"))
        expected = sorted(hdi(draws.isel({level_dim: k}).values, 0.9) for k in range(draws.sizes[level_dim]))
        segments = fig.axes[0].collections[0].get_segments()
        drawn = sorted((s[0][0], s[1][0]) for s in segments)  # x of each HDI line's ends (divided by the axis's scale)
        factor = np.ptp(expected) / np.ptp(drawn)  # the axis's plain-number scale: a power of ten
        assert math.isclose(math.log10(factor), round(math.log10(factor)), abs_tol=1e-9)
        np.testing.assert_allclose(np.array(drawn) * factor, expected, rtol=1e-9)
        legend = [t.get_text() for t in fig.legends[0].get_texts()]
        assert any("90% HDI" in t for t in legend) and not any("94" in t for t in legend)
    finally:
        plt.close(fig)


def test_units_in_unit_cells_are_written_as_a_physicist_writes_them(written):
    assert ascii_units(_tables(written)) == []
    html = written.read_text(encoding="utf-8")
    assert "m²/N²" in html and "kPa" in html and "µm" in html  # eta, E_star and d_air in their display units
    assert pretty_unit("N*s/m") == "N·s/m" and pretty_unit("m^2/N^m") == "m²/Nᵐ"
    assert pretty_unit("N*s/m/N^n_z", html=True) == "N·s/m/N<sup>n<sub>z</sub></sup>"


def test_display_units_scale_the_shown_values_only(written, short_fits):
    """E_star shown in kPa: the page's mean is the CSV's (Pa) over 1000, to its shown precision."""
    plain = short_fits[0]
    summary = plain.summary()
    table = next(t for t in _tables(written) if t["kind"] == "summary")["rows"]
    header, rows = table[0], {r[0]: r for r in table[1:]}
    row = rows["E_star"]
    assert row[header.index("unit")] == "kPa"
    shown, sd = float(row[header.index("mean")]), summary.loc["E_star", "sd"] / 1e3
    assert abs(shown - summary.loc["E_star", "mean"] / 1e3) <= 10 ** sd_resolution(sd) / 2 + 1e-12
    csv = (written.parent / "plain_summary.csv").read_text()
    assert repr(float(summary.loc["E_star", "mean"])) in csv  # the CSV keeps every digit, in SI


@pytest.mark.parametrize("prob", [0.94, 0.9])
def test_fit_summary_is_arviz_summary_at_the_same_setting(short_fits, prob):
    """``fit.summary(ci_prob=p)`` = ``az.summary(fit.idata, ci_prob=p, ci_kind="hdi")``: the same
    means, sds and interval ends, to the last digit."""
    from arviz_stats import summary as az_summary

    plain = short_fits[0]
    ours = plain.summary(ci_prob=prob)
    lower, upper = interval_columns(prob)
    theirs = az_summary(plain.idata, group="posterior", ci_prob=prob, ci_kind="hdi", round_to="none")
    theirs.index = [i.replace("'", "") for i in theirs.index]
    pct = f"{100 * prob:g}"
    for name in theirs.index:
        assert ours.loc[name, "mean"] == theirs.loc[name, "mean"]
        assert ours.loc[name, "sd"] == theirs.loc[name, "sd"]
        assert ours.loc[name, lower] == theirs.loc[name, f"hdi{pct}_lb"]
        assert ours.loc[name, upper] == theirs.loc[name, f"hdi{pct}_ub"]
    assert ours.attrs["ci_prob"] == prob and ours.attrs["ci_kind"] == "hdi"
    width = ours[upper] - ours[lower]
    if prob == 0.9:  # a narrower interval than the default's, on every row
        default = plain.summary()
        assert np.all(width.to_numpy() < (default["hdi_97%"] - default["hdi_3%"]).to_numpy())
    assert not math.isnan(float(width.iloc[0]))


def test_a_display_unit_of_another_dimension_is_refused(tmp_path):
    """A card's display unit is parsed and dimension-checked at load: kPa for a modulus is
    taken, mm for a modulus is refused naming the field."""
    card = (Path(skinfit.__file__).parents[1] / "models" / "electroadhesion.toml").read_text()
    assert skinfit.load_model("electroadhesion").parameters[0].display_unit == "kPa"
    bad = tmp_path / "electroadhesion.toml"
    bad.write_text(card.replace('display_unit = "kPa"', 'display_unit = "mm"', 1))
    with pytest.raises(skinfit.InputError, match=r"parameters\[0\]\.display_unit.*dimension of 'Pa'.*'mm'"):
        skinfit.load_model(str(bad))
    bad.write_text(card.replace('display_unit = "kPa"', 'display_unit = "kPaa"', 1))
    with pytest.raises(skinfit.InputError, match="display_unit"):
        skinfit.load_model(str(bad))


def test_contrast_matrix_draws_each_pair_once_each_way():
    """13 subjects whose log modulus rises by 0.1 each: cell (A, B) holds log(A / B) of the
    medians (about 0.1 * (i - j)), antisymmetric, and a dot on each side of every pair whose
    probability of direction exceeds 0.95."""
    import itertools

    import pandas as pd

    from skinfit.analysis.contrasts import contrast
    from skinfit.plots.contrast_matrix import plot_contrast_matrix

    rng = np.random.default_rng(0)
    subjects = {f"S{i:02d}": np.exp(rng.normal(np.log(2e4) + 0.1 * i, 0.1, 4000)) for i in range(13)}
    table = pd.DataFrame([{"A": a, "B": b, "parameter": "E_star", **contrast(subjects[a], subjects[b])}
                          for a, b in itertools.combinations(subjects, 2)])
    fig = plot_contrast_matrix(table, "E_star")
    ax = fig.axes[0]
    values = ax.images[0].get_array()
    np.testing.assert_allclose(values, -values.T)
    i, j = np.triu_indices(13, 1)
    np.testing.assert_allclose(values[i, j], 0.1 * (i - j), atol=0.02)
    assert len(ax.lines[0].get_xdata()) == 2 * int((table["prob_direction"] > 0.95).sum())
    sys.path.insert(0, str(Path(__file__).parent))
    from layout import layout_problems, unplain_ticks

    assert not unplain_ticks(fig) and not layout_problems(fig), (unplain_ticks(fig), layout_problems(fig)[:4])


def test_a_cards_rope_is_read_and_checked(tmp_path):
    """``rope = [low, high]`` on a parameter: the region of practical equivalence its contrasts
    report P in; a reversed one is refused naming the field."""
    card = (Path(skinfit.__file__).parents[1] / "models" / "electroadhesion.toml").read_text()
    marker = 'name = "alpha"\n'
    assert marker in card
    path = tmp_path / "electroadhesion.toml"
    path.write_text(card.replace(marker, marker + "rope = [0.95, 1.05]\n", 1))
    alpha = next(q for q in skinfit.load_model(str(path)).parameters if q.name == "alpha")
    assert alpha.rope == (0.95, 1.05)
    path.write_text(card.replace(marker, marker + "rope = [1.05, 0.95]\n", 1))
    with pytest.raises(skinfit.InputError, match=r"rope.*low < high"):
        skinfit.load_model(str(path))


def test_the_printed_summary_is_rounded_as_the_report(short_fits):
    """``skinfit fit`` prints :meth:`Fit.report_text`: its table at the precision each sd
    allows, under a line naming the interval."""
    text = short_fits[0].report_text()
    lines = text.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("intervals: 94% HDI"))
    header = ["parameter", *lines[at + 1].split()]
    numeric = header[: header.index("contraction") + 1]
    rows = [line.split()[: len(numeric)] for line in lines[at + 2:] if line.strip()]
    assert len(rows) == len(short_fits[0].summary())
    assert too_precise([numeric, *rows]) == []
    assert too_precise([numeric, [*rows[0][:2], "37012.345", *rows[0][3:]]]) != []  # the check reads these rows


def test_population_rows_name_their_unit_in_display_units():
    """The population table's unit column: natural rows in the card's display unit (values
    scaled), mu of a log coordinate as ln of that unit (shifted by ln 1000 for kPa), its tau
    and correlations dimensionless, no unit written in ASCII."""
    from skinfit.report.tables import cells, population_units

    hyper = pd.DataFrame({"quantity": ["median", "mu", "tau", "mu", "tau", "corr"],
                          "estimate": [2e5, math.log(2e5), 0.3, 3e-7, 1e-7, 0.2],
                          "sd": [1e4, 0.05, 0.02, 1e-8, 1e-8, 0.1],
                          "lower": [1.8e5, math.log(1.8e5), 0.27, 2.8e-7, 0.8e-7, 0.0],
                          "upper": [2.2e5, math.log(2.2e5), 0.33, 3.2e-7, 1.2e-7, 0.4],
                          "coordinate": ["natural", "log", "log", "natural", "natural", "population"]},
                         index=pd.Index(["E", "E", "E", "a", "a", "E,a"], name="parameter"))
    shown = population_units(hyper, {"E": "kPa"}, {"E": "Pa", "a": "m^2/N^m"})
    assert list(shown.columns[:2]) == ["quantity", "unit"]
    assert [str(u) for u in shown["unit"]] == ["kPa", "ln(kPa)", "-", "m²/N<sup>m</sup>", "m²/N<sup>m</sup>", "-"]
    np.testing.assert_allclose(shown["estimate"], [200, math.log(200), 0.3, 3e-7, 1e-7, 0.2], rtol=1e-12)
    np.testing.assert_allclose(shown["sd"], [10, 0.05, 0.02, 1e-8, 1e-8, 0.1], rtol=1e-12)
    np.testing.assert_allclose(shown["upper"][:2], [220, math.log(220)], rtol=1e-12)
    assert np.allclose(hyper["estimate"].iloc[0], 2e5)  # the table given (and its CSV) unchanged
    table = cells(shown, "parameter")
    assert ascii_units([{"rows": [table["columns"]] + [[re.sub(r"<[^>]+>", "", c) for c in r]
                                                       for r in table["rows"]]}]) == []
    assert ascii_units([{"rows": [["p", "unit"], ["a", "m^2/N^m"]]}]) == ["m^2/N^m"]  # the checker sees ASCII


def test_a_fits_parameters_split_by_one_column_share_one_forest_figure(tmp_path):
    """Parameters split by the same column are drawn side by side (one job, a panel each), one
    split by another column apart; the forest's caption names the report's interval."""
    import xarray as xr

    from skinfit.report.figures import fit_figure_jobs

    def var(*dims):
        return (("chain", "draw", *dims), np.zeros((2, 3) + (2,) * len(dims)))

    post = xr.Dataset({"alpha": var("voltage"), "c": var(), "beta": var("voltage"), "gamma": var("speed")})

    class Stub:
        def group(self, name):
            return post

    jobs = fit_figure_jobs(Stub(), 0, "k", tmp_path, n_of_model=5, where="here", ci_prob=0.8)
    forests = [j for j in jobs if j["func"] == "plot_forest"]
    assert [j["args"] for j in forests] == [(["alpha", "beta"],), (["gamma"],)]
    assert [j["path"].name for j in forests] == ["k_forest_voltage.png", "k_forest_gamma.png"]
    assert forests[0]["entry"]["caption"] == "alpha, beta per voltage (a panel each): posterior mean and 80% HDI"
    assert all(j["kwargs"] == {"ci_prob": 0.8} for j in forests)


def test_effects_and_shrunk_tables_name_their_unit_in_display_units():
    """The population's effects: a population value or a difference of means in the parameter's
    display unit (values scaled), a ratio of medians dimensionless; a subject table of one
    parameter scaled to its display unit and named with it. The tables given stay in SI."""
    from skinfit.report.tables import effect_units, in_display_unit

    effects = pd.DataFrame({"parameter": ["m1", "E[M10] vs E[M01]", "E[M10] vs E[M01]"],
                            "question": ["population mean of m1 vs 0", "difference of means", "ratio of medians"],
                            "estimate": [0.3, 2e4, 1.2], "sd": [0.1, 5e3, 0.1], "lower": [0.1, 1e4, 1.0],
                            "upper": [0.5, 3e4, 1.4], "p_above": [0.99, 0.999, 0.97]})
    shown = effect_units(effects, {"E": "kPa"}, {"E": "Pa", "m1": "1/N"})
    assert list(shown.columns[:3]) == ["parameter", "question", "unit"]
    assert [str(u) for u in shown["unit"]] == ["1/N", "kPa", "-"]
    np.testing.assert_allclose(shown["estimate"], [0.3, 20, 1.2], rtol=1e-12)
    np.testing.assert_allclose(shown["upper"], [0.5, 30, 1.4], rtol=1e-12)
    np.testing.assert_allclose(shown["p_above"], effects["p_above"])  # probabilities are not scaled
    assert effects["estimate"].iloc[1] == 2e4
    subjects = pd.DataFrame({"sd": [1e3], "separate": [2e5], "separate_lower": [1.8e5], "shrunk": [1.9e5],
                             "contraction": [0.9]}, index=pd.Index(["S01"], name="subject"))
    table, unit = in_display_unit(subjects, "E[M10]", {"E": "kPa"}, {"E": "Pa"})
    assert str(unit) == "kPa" and table.loc["S01", "separate"] == 200 and table.loc["S01", "contraction"] == 0.9
    table, unit = in_display_unit(subjects, "a", {}, {"a": "m^2/N^m"})
    assert str(unit) == "m²/N<sup>m</sup>" and table.loc["S01", "separate"] == 2e5
