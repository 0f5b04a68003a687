"""The data boundary (issue 21 classes 3, 4, 5 for files; issue 22 point 2): data misread silently,
files outside the dataset folder, non-regular or oversized files, and units.

Each test damages a copy of a shipped dataset or builds a small CSV / DataFrame, and checks the
one-line InputError names the file, row and column -- or, for valid input, that the values
arrive in SI units equal to a conversion done by hand."""

import hashlib
import os
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import skinfit
from skinfit.errors import InputError
from skinfit.io.data import from_frame, load_dataset, write_card
from skinfit.io.units import parse_unit, si_unit

ROOT = Path(skinfit.__file__).resolve().parents[1]
EA = ROOT / "datasets" / "electroadhesion_synthetic"


@pytest.fixture
def ds_dir(tmp_path):
    d = tmp_path / "ea"
    shutil.copytree(EA, d)
    return d


def _one_line(err):
    assert "\n" not in str(err.value)
    return str(err.value)


# ---- class 3: misread data ------------------------------------------------------------------
def test_class3_extra_fields_are_an_error_naming_the_row(ds_dir):
    lines = (ds_dir / "data.csv").read_text().splitlines()
    lines[5] = lines[5].replace(".", ",", 1)  # a decimal comma on data row 5
    (ds_dir / "data.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"data.csv: column 5, row 5: 5 fields where the header has 4; "
                                         r".*decimal comma") as err:
        load_dataset(str(ds_dir))
    _one_line(err)


def test_class3_every_row_with_an_extra_field_is_not_read_as_an_index(ds_dir):
    # pandas reads a file whose every row has one field more than the header with the first
    # field as the index: every row here is shifted, and must be an error at row 1
    lines = (ds_dir / "data.csv").read_text().splitlines()
    (ds_dir / "data.csv").write_text("\n".join([lines[0]] + [ln.replace(".", ",", 1) for ln in lines[1:]]) + "\n")
    with pytest.raises(InputError, match=r"data.csv: column 5, row 1: 5 fields where the header has 4"):
        load_dataset(str(ds_dir))


def test_class3_missing_fields_are_an_error_naming_the_row(ds_dir):
    lines = (ds_dir / "data.csv").read_text().splitlines()
    lines[3] = lines[3].rsplit(",", 1)[0]
    (ds_dir / "data.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"data.csv: column 4, row 3: 3 fields where the header has 4"):
        load_dataset(str(ds_dir))


def test_class3_duplicated_header_is_an_error_naming_the_column(ds_dir):
    text = (ds_dir / "data.csv").read_text().replace("subject,voltage", "subject,normal_force", 1)
    (ds_dir / "data.csv").write_text(text)
    with pytest.raises(InputError, match=r"data.csv: column 'normal_force': the header names this column twice "
                                         r"\(fields 2 and 3\)"):
        load_dataset(str(ds_dir))
    # the same name with two units is as ambiguous
    text = (EA / "data.csv").read_text().replace("normal_force,tangential_force",
                                                 "normal_force [mN],normal_force [N]", 1)
    (ds_dir / "data.csv").write_text(text)
    with pytest.raises(InputError, match=r"two header fields name column 'normal_force'"):
        load_dataset(str(ds_dir))


def test_class3_two_card_columns_mapped_to_one_model_name_refused(ds_dir):
    card = (ds_dir / "dataset.toml").read_text().replace('[columns.voltage]\n',
                                                         '[columns.voltage]\nname = "normal_force"\n', 1)
    (ds_dir / "dataset.toml").write_text(card)
    with pytest.raises(InputError, match=r"dataset.toml: columns.normal_force.name: columns 'voltage' and "
                                         r"'normal_force' are both read as 'normal_force'"):
        load_dataset(str(ds_dir))


def test_class3_header_unit_disagreeing_with_the_card_refused(ds_dir):
    text = (EA / "data.csv").read_text().replace("normal_force,", "normal_force [N],", 1)
    (ds_dir / "data.csv").write_text(text)
    with pytest.raises(InputError, match=r"column 'normal_force \[N\]': the header says \[N\], the card says 'mN'"):
        load_dataset(str(ds_dir))
    # agreeing: the card's key matches the header's name and the values are the same
    (ds_dir / "data.csv").write_text((EA / "data.csv").read_text().replace("normal_force,", "normal_force [mN],", 1))
    assert np.array_equal(load_dataset(str(ds_dir)).frame["normal_force"], load_dataset(str(EA)).frame["normal_force"])


# ---- class 4: reads outside the dataset folder; messages quote no other file ----------------
def test_class4_card_file_outside_its_folder_refused(ds_dir, tmp_path):
    secret = tmp_path / "secret.csv"
    secret.write_text("root:x:0:0:secret-first-line\n")
    for name in ("../secret.csv", str(secret), "/etc/passwd"):
        card = (ds_dir / "dataset.toml").read_text().replace('file = "data.csv"', f'file = "{name}"')
        (ds_dir / "dataset.toml").write_text(card)
        with pytest.raises(InputError, match=r"dataset.toml: file: must name a file inside the dataset's folder") as err:
            load_dataset(str(ds_dir))
        assert "secret-first-line" not in str(err.value)
        shutil.copy(EA / "dataset.toml", ds_dir / "dataset.toml")


def test_class4_an_explicit_path_to_a_non_data_file_is_not_quoted(tmp_path):
    other = tmp_path / "notes.csv"
    other.write_text("root:x:0:0:secret-first-line:/root:/bin/bash\nsecond\n")
    with pytest.raises(InputError) as err:
        load_dataset(str(other), model="electroadhesion")
    assert "secret" not in str(err.value) and "notes.csv" in str(err.value)


# ---- class 5: only regular files, of bounded size --------------------------------------------
def test_class5_special_files_refused_before_reading(ds_dir, tmp_path):
    fifo = tmp_path / "data.fifo.csv"
    os.mkfifo(fifo)
    (tmp_path / "dir.csv").mkdir()
    for path, kind in ((fifo, "a FIFO"), (tmp_path / "dir.csv", "a directory"), (Path("/dev/zero"), "a device")):
        with pytest.raises(InputError, match=rf"is {kind}, not a regular file"):
            load_dataset(str(path), model="electroadhesion")
    # a card's data file that is a FIFO inside the folder: refused (not waited on)
    (ds_dir / "data.csv").unlink()
    os.mkfifo(ds_dir / "data.csv")
    with pytest.raises(InputError, match=r"data.csv: is a FIFO, not a regular file"):
        load_dataset(str(ds_dir))
    card = ds_dir / "c.toml"
    os.mkfifo(card)
    with pytest.raises(InputError, match=r"c.toml: is a FIFO"):
        skinfit.load_model(str(card))


def test_class5_data_file_above_the_size_limit_refused_with_the_limit(ds_dir, monkeypatch):
    size = (ds_dir / "data.csv").stat().st_size
    with pytest.raises(InputError, match=rf"data.csv: {size / 2**20:.1f} MiB: data file larger than the limit of "
                                         r"0.0 MiB \(raise it with the SKINFIT_MAX_DATA_MB"):
        load_dataset(str(ds_dir), max_bytes=size - 1)
    monkeypatch.setenv("SKINFIT_MAX_DATA_MB", str(size / 2**20 / 2))
    with pytest.raises(InputError, match=r"larger than the limit"):
        load_dataset(str(ds_dir))
    monkeypatch.setenv("SKINFIT_MAX_DATA_MB", str(size / 2**20 * 2))
    assert len(load_dataset(str(ds_dir))) == 216


# ---- units (issue 22 point 2) ---------------------------------------------------------------
@pytest.mark.parametrize("unit, factor", [("mN", 1e-3), ("um", 1e-6), ("µm", 1e-6), ("μm", 1e-6), ("mm^2", 1e-6),
                                          ("mm/s", 1e-3), ("kPa", 1e3), ("kHz", 1e3), ("deg", np.pi / 180),
                                          ("N*s/m", 1.0), ("cm", 1e-2), ("g", 1e-3), ("min", 60.0),
                                          ("mm/h", 1e-3 / 3600)])
def test_units_converted_to_si_by_hand_factors(unit, factor):
    assert parse_unit(unit).factor == pytest.approx(factor, rel=1e-12)


def test_units_outside_the_grammar_refused_and_stored_in_si():
    """Units the grammar does not read (imperial, offset scales) are refused, never guessed
    (tests/test_units.py checks the grammar against pint); read ones are stored in SI."""
    for text in ("inch", "degC", "psi"):
        with pytest.raises(ValueError, match="unknown unit"):
            parse_unit(text)
    assert si_unit("mN") == "N" and si_unit("um") == "m" and si_unit("deg") == "rad" and si_unit("MPa") == "Pa"


def _ea_csv(tmp_path, header="subject,voltage [V],normal_force [mN],tangential_force [mN]", name="my.csv"):
    frame = load_dataset("electroadhesion_synthetic").frame
    path = tmp_path / name
    rows = [f"{s},{v:g},{fn * 1e3:.17g},{ft * 1e3:.17g}" for s, v, fn, ft in frame.itertuples(index=False)]
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize("header, column, match", [
    ("voltage [V],normal_force [mm]", "normal_force [mm]", r"unit 'mm' is a length; model 'electroadhesion' needs "
                                                           r"normal_force as a force"),
    ("voltage [kHz],normal_force [mN]", "voltage [kHz]", r"unit 'kHz' is a frequency; .* voltage as a voltage"),
    ("voltage [V],normal_force [1]", "normal_force [1]", r"unit '1' is a dimensionless quantity; .* as a force"),
    ("voltage [V],normal_force [blorgs]", "normal_force [blorgs]", r"unknown unit 'blorgs'"),
])
def test_units_of_the_wrong_dimension_refused_naming_the_column(tmp_path, header, column, match):
    path = _ea_csv(tmp_path, f"subject,{header},tangential_force [mN]")
    with pytest.raises(InputError, match=rf"my.csv: column '{column.replace('[', r'\[').replace(']', r'\]')}': {match}"):
        load_dataset(str(path), model="electroadhesion")


def test_csv_with_units_in_its_header_equals_the_shipped_dataset_in_si(tmp_path):
    ds = load_dataset(str(_ea_csv(tmp_path)), model="electroadhesion")
    ref = load_dataset("electroadhesion_synthetic")
    for c in ("voltage", "normal_force", "tangential_force"):
        np.testing.assert_allclose(ds.frame[c], ref.frame[c], rtol=1e-15)
    assert ds.units == {"voltage": "V", "normal_force": "mN", "tangential_force": "mN"}
    assert ds.provenance["sha256"] == hashlib.sha256((tmp_path / "my.csv").read_bytes()).hexdigest()
    # a quantity of the model without a unit: an error saying how to give it
    path = _ea_csv(tmp_path, "subject,voltage,normal_force [mN],tangential_force [mN]", "nounit.csv")
    with pytest.raises(InputError, match=r"nounit.csv: column 'voltage': no unit for 'voltage'.*'voltage \[unit\]'"):
        load_dataset(str(path), model="electroadhesion")
    assert load_dataset(str(path), model="electroadhesion", units={"voltage": "V"}).frame["voltage"].equals(
        ref.frame["voltage"])


def test_dataframe_with_units_validated_as_a_csv_is():
    ref = load_dataset("electroadhesion_synthetic").frame
    df = pd.DataFrame({"subject": ref["subject"], "voltage": ref["voltage"], "normal_force": ref["normal_force"] * 1e3,
                       "tangential_force [mN]": ref["tangential_force"] * 1e3})
    ds = skinfit.Dataset.from_frame(df, units={"voltage": "V", "normal_force": "mN"}, model="electroadhesion")
    np.testing.assert_allclose(ds.frame["normal_force"], ref["normal_force"], rtol=1e-15)
    bad = df.copy()
    bad.loc[6, "normal_force"] = -3.0
    with pytest.raises(InputError, match=r"DataFrame 'frame': column 'normal_force', row 7: expected a force >= 0"):
        from_frame(bad, units={"voltage": "V", "normal_force": "mN"}, model="electroadhesion")
    with pytest.raises(InputError, match=r"column 'normal_force': unit 'mm' is a length"):
        from_frame(df, units={"voltage": "V", "normal_force": "mm"}, model="electroadhesion")
    # equal content, equal identity; other content, other identity
    again = from_frame(df.copy(), units={"voltage": "V", "normal_force": "mN"}, model="electroadhesion")
    assert again.sha256 == ds.sha256
    df.loc[0, "normal_force"] += 1e-9
    assert from_frame(df, units={"voltage": "V", "normal_force": "mN"}, model="electroadhesion").sha256 != ds.sha256


def test_written_card_reloads_the_same_data_and_detects_a_changed_file(tmp_path):
    ds = load_dataset(str(_ea_csv(tmp_path)), model="electroadhesion")
    card = write_card(ds, tmp_path / "run" / "dataset")
    again = load_dataset(str(card.parent))
    pd.testing.assert_frame_equal(again.frame, ds.frame)
    assert again.provenance["sha256"] == ds.provenance["sha256"] and again.model == "electroadhesion"
    data = card.parent / "data.csv"
    data.write_text(data.read_text().replace("S01", "S02", 1))
    with pytest.raises(InputError, match=r"dataset.toml: provenance.sha256: data.csv is not the file this card"):
        load_dataset(str(card.parent))


def test_cli_fits_a_csv_without_a_card_and_writes_one_that_reproduces_the_fit(tmp_path, capsys):
    from skinfit.apps.cli import main

    csv = _ea_csv(tmp_path)
    assert main(["fit", "electroadhesion", str(csv), "--out", str(tmp_path / "a"), "--seed", "5", "--quiet"]) == 0
    card = tmp_path / "a" / "dataset" / "dataset.toml"
    assert card.exists()
    assert main(["fit", "electroadhesion", str(card.parent), "--out", str(tmp_path / "b"), "--seed", "5",
                 "--quiet"]) == 0
    a, b = skinfit.load_fit(tmp_path / "a" / "fit.nc"), skinfit.load_fit(tmp_path / "b" / "fit.nc")
    assert np.array_equal(a.idata["posterior"]["phi"].values, b.idata["posterior"]["phi"].values)
    # root attrs: the stored values' units are SI, the units the data came in kept apart
    assert a.attr("units")["normal_force"] == "N" and a.attr("data_units")["normal_force"] == "mN"
    assert a.idata["observed_data"]["tangential_force"].attrs["units"] == "N"
    assert a.idata["posterior"]["E_star"].attrs["units"] == "Pa"
    # the data came in mN: the stored observations are the same numbers / 1000
    np.testing.assert_allclose(a.idata["observed_data"]["tangential_force"].values,
                               load_dataset("electroadhesion_synthetic").frame["tangential_force"], rtol=1e-15)


def test_cli_by_group_on_a_csv_without_a_card_writes_its_card(tmp_path, capsys):
    from skinfit.apps.cli import main

    csv = _ea_csv(tmp_path)
    assert main(["fit", "electroadhesion", str(csv), "--by", "subject", "--out", str(tmp_path / "g"), "--seed", "2",
                 "--quiet"]) == 0
    card = tmp_path / "g" / "dataset" / "dataset.toml"
    assert load_dataset(str(card.parent)).provenance["sha256"] == hashlib.sha256(csv.read_bytes()).hexdigest()
