"""Lab tables as exported (issue 41, point 1): a CSV with comment lines, ``;`` separators,
decimal commas and ``Name (unit)`` headers; an Excel workbook; MATLAB v5 and v7.3 files; an HDF5
file.  Each is written here the way lab software writes it, mapped by ``skinfit dataset init``
with at most ``--column`` flags, read back through the card equal to the values written
(converted to SI within one rounding of the unit's factor), and fitted.  Every ambiguity is a
one-line error naming the file, the column and the row as the user sees the file."""

import hashlib
import sys
from fractions import Fraction
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
import scipy.io

import skinfit
from skinfit.apps.cli import main
from skinfit.errors import InputError, InputTypeError, MissingDependency
from skinfit.io.data import from_frame, load_dataset, write_card
from skinfit.io.mapping import init_dataset
from skinfit.io.tables import read_lab_table

ROOT = Path(skinfit.__file__).resolve().parents[1]
MODEL = "electroadhesion_coulomb"  # covariates normal_force [N], voltage [V]; observable tangential_force [N]
QUICK = dict(rng=1, max_steps=40, n_global=50, ess_target=5, n_prior_draws=20, complete=False)


@pytest.fixture(scope="module")
def lab():
    """18 rows of the shipped synthetic data, as text in lab units (mN, V): the values written."""
    text = pd.read_csv(ROOT / "datasets" / "electroadhesion_synthetic" / "data.csv", dtype=str).iloc[::12]
    return text.reset_index(drop=True)


def _si(texts, factor):
    """The exact SI value of each decimal text (``factor`` a Fraction), rounded once to float."""
    return np.array([float(Fraction(t) * factor) for t in texts])


def _check_values(ds, lab):
    """The dataset holds the values written: mN -> N within one rounding (the conversion is one
    multiplication by the factor 1e-3, itself a rounded number), volts exactly."""
    np.testing.assert_array_max_ulp(ds.frame["normal_force"].to_numpy(), _si(lab.normal_force, Fraction(1, 1000)), 1)
    np.testing.assert_array_max_ulp(ds.frame["tangential_force"].to_numpy(),
                                    _si(lab.tangential_force, Fraction(1, 1000)), 1)
    np.testing.assert_array_equal(ds.frame["voltage"].to_numpy(), _si(lab.voltage, Fraction(1)))
    assert ds.frame["normal_force"].iloc[0] == 0.2  # "200.000" mN is 0.2 N


def _fits(folder, ds):
    fit = skinfit.fit(MODEL, str(folder), **QUICK)
    assert fit.attrs["dataset_sha256"] == ds.sha256  # the fit read the file through the card
    return fit


def _lab_csv(lab, path, *, sep=";", comma=True, encoding="latin-1"):
    def num(t):
        return t.replace(".", ",") if comma else t

    lines = ["# exported by RigSoft 2.1 on 2026-11-20", "% operator: A. B.",
             sep.join(["Subject", "Normal force (mN)", "Ft", "Voltage (V)", "Temperature (°C)"])]
    lines += [sep.join([s, num(fn), num(ft), num(v), num("21.5")])
              for s, fn, ft, v in zip(lab.subject, lab.normal_force, lab.tangential_force, lab.voltage)]
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode(encoding))
    return path


# ---- CSV ------------------------------------------------------------------------------------
def test_csv_as_exported_needs_one_column_flag_and_fits(lab, tmp_path, capsys):
    src = _lab_csv(lab, tmp_path / "trial 3.csv")
    code = main(["dataset", "init", str(src), "--model", MODEL, "--out", str(tmp_path / "ds"),
                 "--column", "Ft=tangential_force:mN"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert ("csv: sep ';' (detected), decimal ',' (detected), comment '#%' (detected), "
            "encoding 'latin-1' (detected)") in out
    assert "'Normal force (mN)' -> normal_force [mN]" in out and "'Ft'" in out
    card = (tmp_path / "ds" / "dataset.toml").read_text()
    assert 'from = "Normal force (mN)"' in card and 'sep = ";"' in card and 'decimal = ","' in card
    assert (tmp_path / "ds" / "trial 3.csv").read_bytes() == src.read_bytes()  # the original, unchanged
    assert hashlib.sha256(src.read_bytes()).hexdigest() in card
    ds = load_dataset(tmp_path / "ds")  # from Python, through the card
    _check_values(ds, lab)
    assert ds.groups == ("subject",)  # labels kept as a group; the temperature (numbers) is kept, not a group
    assert ds.frame["temperature_c"].eq("21.5").all()
    _fits(tmp_path / "ds", ds)


def test_csv_fitted_from_the_command_line(lab, tmp_path, capsys):
    src = _lab_csv(lab, tmp_path / "lab.csv", sep="\t", encoding="utf-8")
    assert main(["dataset", "init", str(src), "--model", MODEL, "--out", str(tmp_path / "ds"),
                 "--column", "Ft=tangential_force:mN"]) == 0
    assert "sep 'tab' (detected)" in capsys.readouterr().out
    code = main(["fit", MODEL, str(tmp_path / "ds"), "--out", str(tmp_path / "run"), "--max-steps", "40",
                 "--ess", "5", "--quiet", "--seed", "1"])
    assert code == 0, capsys.readouterr().err
    assert (tmp_path / "run" / "fit.nc").exists()


def test_csv_given_options_are_used_not_detected(lab, tmp_path):
    src = _lab_csv(lab, tmp_path / "lab.csv")
    ds, table, _, _ = init_dataset(src, MODEL, tmp_path / "ds", columns={"Ft": "tangential_force"},
                                   units={"Ft": "mN"}, read={"sep": ";", "decimal": ",", "comment": "#%",
                                                             "encoding": "cp1252"})
    assert table.detected == () and table.read["encoding"] == "cp1252"
    _check_values(ds, lab)


@pytest.mark.parametrize("edit, match", [
    # a value that is no number: the row is the file's line (2 comment lines + header before row 1)
    (lambda lines: lines.__setitem__(6, lines[6].replace("S01;", "S01;abc;", 1).replace(";21,5", "")),
     r"trial\.csv: column 'Normal force \(mN\)', row 7: expected a number in mN \(got 'abc'\)"),
    # a decimal point among decimal commas: 1.500 may be a thousands mark
    (lambda lines: lines.__setitem__(8, lines[8].replace(",", ".", 1)),
     r"trial\.csv: column 'Normal force \(mN\)', row 9: '1181\.818' is written with the other decimal mark than "
     r"'200,000' \(column 'Normal force \(mN\)', row 4\): give the decimal mark"),
    # a negative force
    (lambda lines: lines.__setitem__(5, lines[5].replace("S01;", "S01;-", 1)),
     r"trial\.csv: column 'Normal force \(mN\)', row 6: expected a force >= 0"),
    # a row with a field more than the header
    (lambda lines: lines.__setitem__(10, lines[10] + ";7"),
     r"trial\.csv: column 6, row 11: 6 fields where the header has 5"),
    # two headers that read as one name
    (lambda lines: lines.__setitem__(2, lines[2].replace("Temperature (°C)", "normal_force [N]")),
     r"trial\.csv: columns 'Normal force \(mN\)' and 'normal_force \[N\]', row 3: both read as 'normal_force'"),
    # no header the model's observable reads as (and no --column for it)
    (lambda lines: lines.__setitem__(2, lines[2].replace("Ft", "Friction")),
     r"trial\.csv: column 'tangential_force': model 'electroadhesion_coulomb' needs tangential_force \[N\] and no "
     r"header reads as it .*--column \"HEADER=tangential_force\""),
])
def test_csv_ambiguity_names_file_column_and_row(lab, tmp_path, edit, match):
    path = _lab_csv(lab, tmp_path / "trial.csv", encoding="utf-8")
    lines = path.read_text(encoding="utf-8").splitlines()
    edit(lines)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(InputError, match=match) as err:
        init_dataset(path, MODEL, tmp_path / "ds", columns={"Ft": "tangential_force"} if "Ft" in lines[2] else None,
                     units={"Ft": "mN"} if "Ft" in lines[2] else None)
    assert "\n" not in str(err.value)
    assert not (tmp_path / "ds").exists()  # nothing written


def test_csv_separator_that_could_be_two_is_an_error(tmp_path):
    path = tmp_path / "odd.csv"
    path.write_text("a,b;c,d\n1,2;3,4\n")
    with pytest.raises(InputError, match=r"odd\.csv: sep, row 1: the separator could be ',' \(3 columns\) or ';' "
                                          r"\(2 columns\): give it"):
        init_dataset(path, MODEL, tmp_path / "ds")


@pytest.mark.parametrize("encoding, bom, expected", [
    ("utf-8", b"", "utf-8"), ("utf-8", b"\xef\xbb\xbf", "utf-8-sig"), ("cp1252", b"", "cp1252"),
    ("latin-1", b"", "latin-1"),
])
def test_the_encoding_is_detected_and_the_text_read_as_written(encoding, bom, expected):
    label = "Müller €" if encoding in ("utf-8", "cp1252") else "Müller µ"
    raw = bom + f"subject;Fn (µN)\n{label};1,5\n".encode(encoding)
    table = read_lab_table(raw, "x.csv")
    assert table.read["encoding"] == expected and "encoding" in table.detected
    assert table.headers == ("subject", "Fn (µN)") and list(table.cells["subject"]) == [label]
    assert list(table.cells["Fn (µN)"]) == ["1.5"] and table.read["decimal"] == ","
    assert list(table.rows) == [2]


def test_a_title_line_above_the_header_is_named(tmp_path):
    path = tmp_path / "titled.csv"
    path.write_text("RigSoft export\nFn;Ft\n1;2\n")
    with pytest.raises(InputError, match=r"titled\.csv: header, row 1: the first line has one field and the lines "
                                          r"below 2 \(separated by ';'\): a title line above the header\?"):
        init_dataset(path, MODEL, tmp_path / "ds")
    with pytest.raises(InputError, match=r"titled\.csv: column 2, row 2: 2 fields where the header has 1 \(line 1, "
                                          r"read as the header, has one field: a title line\?"):
        init_dataset(path, MODEL, tmp_path / "ds", read={"sep": ";"})


def test_unit_given_and_in_the_header_must_agree(lab, tmp_path):
    path = _lab_csv(lab, tmp_path / "lab.csv")
    with pytest.raises(InputError, match=r"lab\.csv: column 'Normal force \(mN\)', row 3: the header says 'mN', "
                                         r"the given says 'N'"):
        init_dataset(path, MODEL, tmp_path / "ds", columns={"Ft": "tangential_force"},
                     units={"Ft": "mN", "Normal force (mN)": "N"})


# ---- Excel ----------------------------------------------------------------------------------
def _workbook(lab, path, *, second=False):
    openpyxl = pytest.importorskip("openpyxl")
    book = openpyxl.Workbook()
    ws = book.active
    ws.title = "Trials"
    ws.append(["# friction rig, session 4"])
    ws.append([])
    ws.append(["subject", "normal_force [mN]", "tangential_force [mN]", "voltage [V]"])
    for row in zip(lab.subject, lab.normal_force, lab.tangential_force, lab.voltage):
        ws.append([row[0], *(float(v) for v in row[1:])])
    book.create_sheet("Notes")  # empty: not a second table
    if second:
        book["Notes"].append(["x"])
    book.save(path)
    return path


def test_xlsx_needs_no_flag_and_fits(lab, tmp_path, capsys):
    src = _workbook(lab, tmp_path / "session.xlsx")
    assert main(["dataset", "init", str(src), "--model", MODEL, "--out", str(tmp_path / "ds")]) == 0
    assert "xlsx: comment '#' (detected), sheet 'Trials' (detected)" in capsys.readouterr().out
    ds = load_dataset(tmp_path / "ds")
    _check_values(ds, lab)
    _fits(tmp_path / "ds", ds)
    # without a card, its skinfit headers suffice (never "not UTF-8 text")
    _check_values(load_dataset(src, model=MODEL), lab)


def test_xlsx_errors_name_the_sheet_row(lab, tmp_path):
    src = _workbook(lab, tmp_path / "two.xlsx", second=True)
    with pytest.raises(InputError, match=r"two\.xlsx: sheet: 2 sheets hold data \('Trials', 'Notes'\): name one"):
        init_dataset(src, MODEL, tmp_path / "ds")
    openpyxl = pytest.importorskip("openpyxl")
    book = openpyxl.load_workbook(src)
    book["Trials"]["B7"] = "n/a?"  # sheet row 7: the 3rd data row (a comment row and a blank row above the header)
    book.save(src)
    with pytest.raises(InputError, match=r"two\.xlsx: column 'normal_force \[mN\]', row 7: expected a number in mN"):
        init_dataset(src, MODEL, tmp_path / "ds", read={"sheet": "Trials"})


def test_xlsx_without_openpyxl_names_the_extra(lab, tmp_path, monkeypatch):
    src = _workbook(lab, tmp_path / "s.xlsx")
    monkeypatch.setitem(sys.modules, "openpyxl", None)  # as if not installed
    with pytest.raises(MissingDependency, match=r"pip install 'skinfit\[excel\]'") as err:
        init_dataset(src, MODEL, tmp_path / "ds")
    assert "\n" not in str(err.value)


# ---- MATLAB ---------------------------------------------------------------------------------
def _vectors(lab):
    return {"Fn": lab.normal_force.to_numpy(dtype=float, copy=True),
            "Ft": lab.tangential_force.to_numpy(dtype=float, copy=True), "V": lab.voltage.to_numpy(dtype=float, copy=True)}


FLAGS = ["--column", "Fn=normal_force:mN", "--column", "Ft=tangential_force:mN", "--column", "V=voltage:V"]


def test_mat_v5_struct_with_column_flags_fits(lab, tmp_path, capsys):
    src = tmp_path / "S01.mat"
    data = _vectors(lab) | {"subject": np.array(list(lab.subject), dtype=object)}
    scipy.io.savemat(src, {"data": {k: v.reshape(-1, 1) for k, v in data.items()}, "fs": 1000.0})
    assert main(["dataset", "init", str(src), "--model", MODEL, "--out", str(tmp_path / "ds"), *FLAGS]) == 0
    assert "mat: variable 'data' (detected)" in capsys.readouterr().out
    ds = load_dataset(tmp_path / "ds")
    _check_values(ds, lab)
    assert list(ds.frame["subject"]) == list(lab.subject)
    _fits(tmp_path / "ds", ds)


def test_mat_v5_vectors_at_top_level_and_their_errors(lab, tmp_path):
    src = tmp_path / "top.mat"
    scipy.io.savemat(src, _vectors(lab))
    ds, table, _, _ = init_dataset(src, MODEL, tmp_path / "ds", columns={"Fn": "normal_force", "Ft": "tangential_force",
                                                                          "V": "voltage"},
                                   units={"Fn": "mN", "Ft": "mN", "V": "V"})
    assert table.read["variable"] == "/"
    _check_values(ds, lab)
    short = _vectors(lab)
    short["Ft"] = short["Ft"][:-1]
    scipy.io.savemat(src, short)
    with pytest.raises(InputError, match=r"top\.mat: column 'Ft': vectors of different lengths in the top level of "
                                         r"the file: 'Ft' has 17 values, 'Fn' has 18"):
        init_dataset(src, MODEL, tmp_path / "ds2")
    scipy.io.savemat(src, {"a": {"Fn": np.ones(3)}, "b": {"Fn": np.ones(3)}})
    with pytest.raises(InputError, match=r"top\.mat: variable: holds 2 tables \(a, b\): name one"):
        init_dataset(src, MODEL, tmp_path / "ds3")
    bad = _vectors(lab)
    bad["Fn"][4] = np.nan  # element 5
    scipy.io.savemat(src, bad)
    with pytest.raises(InputError, match=r"top\.mat: column 'Fn', row 5: missing value"):
        init_dataset(src, MODEL, tmp_path / "ds4", columns={"Fn": "normal_force", "Ft": "tangential_force",
                                                            "V": "voltage"}, units={"Fn": "mN", "Ft": "mN", "V": "V"})


def _mat73(path, vectors, struct="data"):
    """A MATLAB v7.3 file as MATLAB writes it: a 512-byte text header (a userblock), then HDF5 with
    each variable transposed ((1, n) for a column vector) and its MATLAB_class attribute."""
    with h5py.File(path, "w", userblock_size=512) as f:
        g = f.create_group(struct)
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        for name, v in vectors.items():
            d = g.create_dataset(name, data=np.asarray(v, dtype=float).reshape(1, -1))
            d.attrs["MATLAB_class"] = np.bytes_("double")
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Fri Nov 20 10:00:00 2026 HDF5 schema 1.00 ."
    with open(path, "r+b") as fh:
        fh.write(header.ljust(116) + b"\0" * 8 + b"\x00\x02IM")


def test_mat_v73_with_column_flags_fits(lab, tmp_path, capsys):
    src = tmp_path / "S01_v73.mat"
    _mat73(src, _vectors(lab))
    assert main(["dataset", "init", str(src), "--model", MODEL, "--out", str(tmp_path / "ds"), *FLAGS]) == 0
    assert "mat: variable 'data' (detected)" in capsys.readouterr().out
    ds = load_dataset(tmp_path / "ds")
    _check_values(ds, lab)
    _fits(tmp_path / "ds", ds)


# ---- HDF5 -----------------------------------------------------------------------------------
def test_h5_group_with_unit_attributes_needs_no_flag_and_fits(lab, tmp_path, capsys):
    src = tmp_path / "session.h5"
    with h5py.File(src, "w") as f:
        f.attrs["rig"] = "tribometer 2"
        g = f.create_group("strokes")
        for name, unit in (("normal_force", "mN"), ("tangential_force", "mN"), ("voltage", "V")):
            g.create_dataset(name, data=lab[name].astype(float).to_numpy()).attrs["unit"] = unit
        g.create_dataset("subject", data=list(lab.subject), dtype=h5py.string_dtype())
    assert main(["dataset", "init", str(src), "--model", MODEL, "--out", str(tmp_path / "ds")]) == 0
    assert "hdf5: variable '/strokes' (detected)" in capsys.readouterr().out
    ds = load_dataset(tmp_path / "ds")
    _check_values(ds, lab)
    _fits(tmp_path / "ds", ds)


def test_card_refuses_a_changed_file(lab, tmp_path):
    src = _lab_csv(lab, tmp_path / "lab.csv")
    init_dataset(src, MODEL, tmp_path / "ds", columns={"Ft": "tangential_force"}, units={"Ft": "mN"})
    copy = tmp_path / "ds" / "lab.csv"
    copy.write_bytes(copy.read_bytes().replace(b"200,000", b"201,000", 1))
    with pytest.raises(InputError, match=r"dataset\.toml: provenance\.sha256: lab\.csv is not the file this card"):
        load_dataset(tmp_path / "ds")


# ---- Python ---------------------------------------------------------------------------------
def test_fit_takes_a_frame_with_columns_and_units(lab, tmp_path):
    frame = pd.DataFrame({"Subject": lab.subject, "Normal force (mN)": lab.normal_force.astype(float),
                          "Ft": lab.tangential_force.astype(float), "V": lab.voltage.astype(float)})
    columns = {"Normal force (mN)": "normal_force", "Ft": "tangential_force", "V": "voltage"}
    units = {"Ft": "mN", "voltage": "V"}
    _check_values(from_frame(frame, columns=columns, units=units, model=MODEL), lab)
    fit = skinfit.fit(MODEL, frame, columns=columns, units=units, **QUICK)
    assert fit.attrs["dataset_sha256"] == from_frame(frame, columns=columns, units=units).sha256
    with pytest.raises(InputError, match=r"DataFrame 'frame': column 'Fx': columns= names a header the table does "
                                         r"not have"):
        from_frame(frame, columns={"Fx": "normal_force"})


@pytest.mark.parametrize("value, match", [
    ({"normal_force": [1.0]}, r"dataset: got a dict: pass a pandas DataFrame: pd\.DataFrame\(d\)"),
    (np.ones((3, 3)), r"dataset: got a numpy\.ndarray: pass a pandas DataFrame with named columns: "
                      r"pd\.DataFrame\(a, columns=\[\.\.\.\]\)"),
    ("xarray", r"dataset: got a xarray\.Dataset: pass a pandas DataFrame: ds\.to_dataframe\(\)\.reset_index\(\)"),
])
def test_what_fit_cannot_take_says_what_to_pass(value, match):
    if isinstance(value, str):
        xr = pytest.importorskip("xarray")
        value = xr.Dataset({"normal_force": ("row", np.ones(3))})
    with pytest.raises(InputTypeError, match=match) as err:
        skinfit.fit(MODEL, value, **QUICK)
    assert "\n" not in str(err.value)


def test_a_workbook_named_csv_is_read_as_one_and_its_card_rereads_it(lab, tmp_path):
    src = _workbook(lab, tmp_path / "export.xlsx").rename(tmp_path / "export.csv")
    ds = load_dataset(src, model=MODEL)  # never "not UTF-8 text"
    _check_values(ds, lab)
    card = write_card(ds, tmp_path / "run" / "dataset")  # as skinfit fit writes it beside a result
    assert 'format = "xlsx"' in card.read_text()
    _check_values(load_dataset(card.parent), lab)


def test_a_comma_that_may_be_a_thousands_mark_is_not_guessed(tmp_path, capsys):
    """``1,234`` with no number in the file settling the mark (every comma followed by three
    digits, no decimal point) is 1.234 or 1234: an error naming the first such cell, until the
    decimal mark is given; one number such as ``0,5`` or ``0,250`` settles it."""
    raw = b"# RigSoft\nsubject;Fn (mN);Ft (mN)\nS1;1,234;500\nS1;2,500;1,250\n"
    with pytest.raises(InputError, match=r"^x\.csv: column 'Fn \(mN\)', row 3: '1,234' reads as 1\.234 with a decimal "
                       r"comma or as 1234 with a thousands separator, .*give the decimal mark \(--decimal ','") as info:
        read_lab_table(raw, "x.csv")
    assert "\n" not in str(info.value)
    table = read_lab_table(raw, "x.csv", {"decimal": ","})
    assert list(table.cells["Fn (mN)"]) == ["1.234", "2.500"] and list(table.cells["Ft (mN)"]) == ["500", "1.250"]
    for settling in ("0,250", "12,25", "1234,567", "1,5e-3"):  # not a thousands grouping: the comma is decimal
        table = read_lab_table(raw.replace(b"500\n", settling.encode() + b"\n"), "x.csv")
        assert table.read["decimal"] == "," and table.cells["Fn (mN)"][0] == "1.234"
    path = tmp_path / "lab.csv"
    path.write_bytes(raw)
    assert main(["dataset", "init", str(path), "--model", MODEL, "--out", str(tmp_path / "ds"),
                 "--column", "Ft (mN)=tangential_force", "--column", "Fn (mN)=normal_force"]) == 2
    assert "lab.csv: column 'Fn (mN)', row 3: '1,234' reads as" in capsys.readouterr().err
