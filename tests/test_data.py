"""The data boundary: units converted to SI, and every bad input named precisely."""

import shutil
from pathlib import Path

import numpy as np
import pytest

import skinfit
from skinfit.io.data import load_dataset

SHIPPED = Path(skinfit.__file__).resolve().parents[1] / "datasets" / "electroadhesion_synthetic"


@pytest.fixture
def ds_dir(tmp_path):
    d = tmp_path / "mydata"
    shutil.copytree(SHIPPED, d)
    return d


def _edit_csv(d, row, column, value):
    lines = (d / "data.csv").read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[row].split(",")
    cells[header.index(column)] = value
    lines[row] = ",".join(cells)
    (d / "data.csv").write_text("\n".join(lines) + "\n")


def test_units_converted_to_si():
    ds = load_dataset("electroadhesion_synthetic")
    raw = (SHIPPED / "data.csv").read_text().splitlines()[1].split(",")
    assert ds.frame["normal_force"].iloc[0] == pytest.approx(float(raw[2]) * 1e-3)  # mN -> N
    assert ds.frame["tangential_force"].iloc[0] == pytest.approx(float(raw[3]) * 1e-3)
    assert ds.units["normal_force"] == "mN"
    assert len(ds) == 216 and ds.provenance["kind"] == "simulated"


def test_dataset_by_path_equals_by_id(ds_dir):
    a, b = load_dataset("electroadhesion_synthetic"), load_dataset(str(ds_dir))
    assert a.sha256 == b.sha256
    np.testing.assert_array_equal(a.frame["tangential_force"], b.frame["tangential_force"])


@pytest.mark.parametrize("row,column,value,match", [
    (7, "normal_force", "-300", r"data.csv: column 'normal_force', row 7: expected a force >= 0 \(got -300 mN"),
    (3, "tangential_force", "abc", r"column 'tangential_force', row 3: expected a number in mN \(got 'abc'\)"),
    (5, "voltage", "", r"column 'voltage', row 5: missing value"),
    (9, "voltage", "NaN", r"column 'voltage', row 9: missing value"),
    (4, "subject", "", r"column 'subject', row 4: empty group label"),
    (2, "normal_force", "inf", r"column 'normal_force', row 2: expected a finite number"),
])
def test_bad_values_name_file_column_row(ds_dir, row, column, value, match):
    _edit_csv(ds_dir, row, column, value)
    with pytest.raises(skinfit.InputError, match=match):
        load_dataset(str(ds_dir))


def test_missing_column(ds_dir):
    text = (ds_dir / "data.csv").read_text().replace("tangential_force", "Ft", 1)
    (ds_dir / "data.csv").write_text(text)
    with pytest.raises(skinfit.InputError, match=r"column 'tangential_force': missing column .*'Ft'"):
        load_dataset(str(ds_dir))


def test_unknown_unit(ds_dir):
    card = (ds_dir / "dataset.toml").read_text()
    (ds_dir / "dataset.toml").write_text(card.replace('unit = "mN"', 'unit = "blorgs"', 1))
    with pytest.raises(skinfit.InputError, match=r"dataset.toml: columns.normal_force.unit: unknown unit 'blorgs'"):
        load_dataset(str(ds_dir))


def test_unit_of_the_wrong_dimension_for_the_cards_model(ds_dir):
    card = (ds_dir / "dataset.toml").read_text()
    (ds_dir / "dataset.toml").write_text(card.replace('unit = "mN"', 'unit = "g"', 1))
    with pytest.raises(skinfit.InputError, match=r"dataset.toml: column 'normal_force': unit 'g' is a "
                       r"\[mass\]; model 'electroadhesion' needs normal_force as a force"):
        load_dataset(str(ds_dir))


def test_empty_file(ds_dir):
    (ds_dir / "data.csv").write_text("")
    with pytest.raises(skinfit.InputError, match="data.csv: the file is empty"):
        load_dataset(str(ds_dir))
    (ds_dir / "data.csv").write_text("subject,voltage,normal_force,tangential_force\n")
    with pytest.raises(skinfit.InputError, match="data.csv: no data rows"):
        load_dataset(str(ds_dir))


def test_bad_toml_and_schema(ds_dir):
    (ds_dir / "dataset.toml").write_text("schema_version = 1\nid = [\n")
    with pytest.raises(skinfit.InputError, match="dataset.toml: invalid TOML"):
        load_dataset(str(ds_dir))
    (ds_dir / "dataset.toml").write_text("schema_version = 7\n")
    with pytest.raises(skinfit.InputError, match=r"schema_version: expected schema_version = 1 \(got 7\)"):
        load_dataset(str(ds_dir))


def test_simulated_data_must_record_seed(ds_dir):
    card = (ds_dir / "dataset.toml").read_text().replace("seed = 20261122\n", "")
    (ds_dir / "dataset.toml").write_text(card)
    with pytest.raises(skinfit.InputError, match="provenance.seed: simulated data must record"):
        load_dataset(str(ds_dir))


def test_signed_column_allows_negative(ds_dir):
    _edit_csv(ds_dir, 7, "normal_force", "-300")
    card = (ds_dir / "dataset.toml").read_text().replace(
        '[columns.normal_force]\nunit = "mN"', '[columns.normal_force]\nunit = "mN"\nsigned = true')
    (ds_dir / "dataset.toml").write_text(card)
    assert load_dataset(str(ds_dir)).frame["normal_force"].iloc[6] == pytest.approx(-0.3)


def test_generator_reproduces_shipped_csv(tmp_path):
    import runpy

    out = tmp_path / "data.csv"
    runpy.run_path(str(SHIPPED / "make.py"), run_name="not_main")["main"](out)
    assert out.read_bytes() == (SHIPPED / "data.csv").read_bytes()


def test_shipped_truth_is_physically_valid():
    import tomllib

    card = tomllib.loads((SHIPPED / "dataset.toml").read_text())
    truth = card["provenance"]["generating_parameters"]
    model = skinfit.load_model("electroadhesion")
    grid = {"normal_force": np.linspace(0.2, 2.0, 50).repeat(9), "voltage": np.tile(np.arange(0, 201, 25.0), 50)}
    _, valid = model.predict(truth, grid, return_valid=True)
    assert valid.all()
