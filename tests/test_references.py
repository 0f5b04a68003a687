"""Every source in the shipped cards and prior files cites a work in skinfit/references.toml."""

import re
import tomllib
from pathlib import Path

import pytest

import skinfit
from skinfit.io.references import check_file_source, check_source, cite, parse_source, references

ROOT = Path(skinfit.__file__).resolve().parents[1]
FILES = sorted([*ROOT.glob("models/*.toml"), *ROOT.glob("priors/*.toml")])


def _sources(doc, prefix=""):
    """(field path, source string) for every `source` anywhere in a TOML document."""
    for key, value in doc.items():
        if isinstance(value, dict):
            yield from _sources(value, f"{prefix}{key}.")
        elif key == "source":
            yield f"{prefix}{key}", value


@pytest.mark.parametrize("path", FILES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_every_source_key_resolves(path):
    sources = list(_sources(tomllib.loads(path.read_text())))
    assert sources, f"{path.name} cites nothing"
    for field, source in sources:
        for key, _ in parse_source(source):
            assert key in references(), f"{path.name}: {field}: unresolved reference key {key!r} in {source!r}"


def test_every_reference_has_a_title_and_every_doi_its_form():
    for key, ref in references().items():
        assert ref["title"].strip(), key
        if "doi" in ref:
            assert re.fullmatch(r"10\.\d{4,9}/\S+", ref["doi"]), key
        if "year" in ref:
            assert 1800 < ref["year"] < 2030, key


def test_no_seed_file_numbers_anywhere_users_read():
    """Sources are cited by key/authors/title, never as 'seed 00N' (the file names of the
    project's private copies of the papers)."""
    pattern = re.compile(r"seed 00\d", re.I)
    for path in [*FILES, *ROOT.glob("datasets/*/dataset.toml"), *ROOT.glob("skinfit/**/*.py"),
                 ROOT / "README.md", *ROOT.glob("docs/**/*.md"), *ROOT.glob("reports/example/*")]:
        if path.is_file():
            assert not pattern.search(path.read_text(errors="replace")), path


def test_a_shipped_file_cites_keys_a_users_may_cite_free_text(tmp_path):
    """Shipped cards and prior files cite keys of references.toml (refused otherwise); a user's
    own file may give free text, recorded and shown as given (issue 42)."""
    text = (ROOT / "priors" / "electroadhesion.toml").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('source = "electroadhesion_friction, Table I range 2-100 kPa',
                                'source = "electroadhesion2020, Table I range 2-100 kPa', 1))
    assert bad.read_text() != text
    source = skinfit.load_priors(str(bad))["E_star"].source
    assert source.startswith("electroadhesion2020, Table I range") and cite(source).startswith(source[:33])
    shipped = ROOT / "priors" / "electroadhesion.toml"
    with pytest.raises(skinfit.InputError, match=r"electroadhesion.toml: E_star.source: .*reference key.*"
                                                 r"'electroadhesion2020'"):
        check_file_source(source, shipped, "priors/electroadhesion.toml", "E_star.source")
    assert check_file_source("Smith et al. 2020, eq. 3", bad, "bad.toml", "source") == "Smith et al. 2020, eq. 3"
    with pytest.raises(skinfit.InputError, match="expected a reference key .*got 'Smith et al. 2020, eq. 3'"):
        check_source("Smith et al. 2020, eq. 3", "card.toml", "source")


def test_a_references_file_on_the_search_path_adds_keys(tmp_path, monkeypatch):

    (tmp_path / "references.toml").write_text('schema_version = 1\n[mylab2026]\ntitle = "Our own model"\n'
                                              'authors = ["A. Researcher"]\nyear = 2026\n')
    monkeypatch.setenv("SKINFIT_PATH", str(tmp_path))
    assert cite("mylab2026, eq. 2") == "Researcher (2026), \u201cOur own model\u201d, eq. 2"
    assert check_source("mylab2026, eq. 2; fujii_wavy, eq. 13", "card.toml", "source")


def test_cite_spells_out_keys_and_keeps_locators():
    assert parse_source("fujii_wavy, Section 6.2: n = -0.3; more on it; dzidek2017: E ~ 40 kPa") == [
        ("fujii_wavy", "Section 6.2: n = -0.3; more on it"), ("dzidek2017", "E ~ 40 kPa")]
    assert cite("fujii_wavy, eq. 13; dzidek2017") == (
        "Fujii, Okamoto & Yamada, \u201cFriction model of fingertip sliding over wavy surface for friction-variable "
        "tactile feedback panel\u201d, eq. 13; Dzidek et al. (2017), \u201cContact mechanics of the human finger pad "
        "under compressive loads\u201d, Journal of the Royal Society Interface 14(127):20160935")


def test_one_citation_style_names_authors_and_year_where_known():
    """Authors (year), title, venue, where: the electroadhesion paper by its authors and year;
    a work without known authors by its title and year; a long author list as 'et al.'."""
    assert cite("electroadhesion_friction, eq. 6").startswith("Basdogan, Sormoli & Sirin (2020), \u201cModeling "
                                                               "Sliding Friction")
    assert cite("electroadhesion_friction, eq. 6").endswith(", IEEE Transactions on Haptics, eq. 6")
    assert cite("textured_elasticity").startswith("\u201cAn Empirical Approach") and "(2019), Biotribology" in \
        cite("textured_elasticity")
    assert cite("torres_ultrasonic").startswith("Torres et al., \u201cMechanisms")
    assert cite("adams2013").startswith("Adams et al. (2013)")  # the file's list ends in "et al."


@pytest.mark.parametrize("path", sorted(ROOT.glob("models/*.toml")), ids=lambda p: p.stem)
def test_every_card_links_to_its_model_documentation(path):
    m = re.search(r"docs/models/[a-z_]+\.md", path.read_text())
    assert m and (ROOT / m.group(0)).is_file(), path.name
    assert path.stem in (ROOT / m.group(0)).read_text() or path.stem in (ROOT / "docs/models/index.md").read_text()
