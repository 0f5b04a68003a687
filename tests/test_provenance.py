"""Class: a fit's inputs silently replaced. A file on the search path that hides a shipped one
(a prior file left in the user folder) is said when the fit starts; every fit records and
prints the model card, prior file and data file it read (path and sha256, checked here
against the files' bytes); a --path or $SKINFIT_PATH folder that does not exist is an error."""

import hashlib
import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import pandas as pd
import pytest

import skinfit
import skinfit.io.paths
import skinfit.io.registry
from skinfit.apps.cli import main
from skinfit.io.provenance import ShadowWarning

ROOT = Path(skinfit.__file__).resolve().parents[1]
MODEL, DATA = "electroadhesion_coulomb", "electroadhesion_synthetic"
QUICK = ["--seed", "1", "--ess", "50", "--max-steps", "300", "--quiet"]


def _sha(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@pytest.fixture
def user(tmp_path, monkeypatch):
    """An empty user folder under tmp_path, no $SKINFIT_PATH, --path or plug-in folders."""
    monkeypatch.delenv("SKINFIT_PATH", raising=False)
    monkeypatch.setattr(skinfit.io.registry, "plugin_folders", list)
    monkeypatch.setattr(skinfit.io.paths, "user_root", lambda: tmp_path / "user")
    skinfit.io.paths.set_search_path([])
    yield tmp_path / "user"
    skinfit.io.paths.set_search_path([])


def _fit(argv, capsys):
    """The CLI run in this process: (its printout, the warnings it gave)."""
    capsys.readouterr()
    with warnings.catch_warnings(record=True) as given:
        assert main(argv) == 0
    return capsys.readouterr(), given


def test_class_input_provenance_a_user_folder_prior_that_hides_the_shipped_one_is_said(tmp_path, monkeypatch):
    """A prior file left in the user folder (E_star median 40 -> 90 kPa) is used, as the search
    path says, but no longer silently: `skinfit fit` warns in one line naming both files, and the
    fit records and prints the file it read with its sha256; model card and data are the shipped
    ones, with theirs. (Run as a user runs it: a process whose user folder is under tmp_path.)"""
    shipped = ROOT / "priors" / f"{MODEL}.toml"
    edited = tmp_path / "xdg" / "skinfit" / "priors" / f"{MODEL}.toml"  # platformdirs' user_data_dir on Linux
    edited.parent.mkdir(parents=True)
    edited.write_text(shipped.read_text().replace("median = 40e3", "median = 90e3"))
    out = tmp_path / "run"
    env = {k: v for k, v in os.environ.items() if k != "SKINFIT_PATH"} | {"XDG_DATA_HOME": str(tmp_path / "xdg"),
                                                                          "MPLBACKEND": "Agg"}
    printed = subprocess.run([sys.executable, "-m", "skinfit", "fit", MODEL, DATA, "--out", str(out), *QUICK],
                             capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600)
    assert printed.returncode == 0, printed.stderr[-2000:]
    shadow = [line for line in printed.stderr.splitlines() if "ShadowWarning" in line]
    assert len(shadow) == 1 and str(edited) in shadow[0] and str(shipped) in shadow[0] and "(shipped)" in shadow[0]
    assert f"prior file: {edited} (user folder), sha256 {_sha(edited)}" in printed.stdout
    card = ROOT / "models" / f"{MODEL}.toml"
    assert f"model card: {card} (shipped), sha256 {_sha(card)}" in printed.stdout
    data = ROOT / "datasets" / DATA / "data.csv"
    assert f"data file:  {data} (sha256 {_sha(data)})" in printed.stdout

    fit = skinfit.load_fit(out)
    inputs = fit.inputs
    assert inputs["priors"]["path"] == str(edited) and inputs["priors"]["sha256"] == _sha(edited)
    assert inputs["priors"]["origin"] == "user"
    assert inputs["priors"]["shadows"] == [{"path": str(shipped), "origin": "shipped", "sha256": _sha(shipped)}]
    assert inputs["model"]["path"] == str(ROOT / "models" / f"{MODEL}.toml") and inputs["model"]["shadows"] == []
    assert inputs["dataset"]["file"] == str(data) and inputs["dataset"]["file_sha256"] == _sha(data)
    assert inputs["dataset"]["path"] == str(ROOT / "datasets" / DATA / "dataset.toml")
    assert "WARNING: the prior file used is" in fit.report_text()
    monkeypatch.delenv("SKINFIT_PATH", raising=False)
    monkeypatch.setattr(skinfit.io.paths, "user_root", lambda: edited.parents[1])  # that user folder, in this process
    with pytest.warns(ShadowWarning, match="prior file used is .* other content"):
        skinfit.fit(MODEL, DATA, rng=1, ess_target=20, max_steps=100)
    assert json.loads(fit.attrs["inputs"])["priors"]["path"] == str(edited)  # in the saved file's attributes


def test_class_input_provenance_an_identical_copy_is_recorded_not_warned(user, tmp_path, capsys):
    """A byte-identical copy of the shipped file in the user folder changes nothing: no warning,
    but the fit still records which of the two it read."""
    copy = user / "priors" / f"{MODEL}.toml"
    copy.parent.mkdir(parents=True)
    copy.write_bytes((ROOT / "priors" / f"{MODEL}.toml").read_bytes())
    printed, given = _fit(["fit", MODEL, DATA, "--out", str(tmp_path / "run"), *QUICK, "--json"], capsys)
    assert not [w for w in given if issubclass(w.category, ShadowWarning)]
    doc = json.loads(printed.out)
    assert doc["inputs"]["priors"]["path"] == str(copy) and doc["inputs"]["priors"]["origin"] == "user"


def test_class_input_provenance_a_run_by_groups_prints_and_indexes_its_inputs(user, tmp_path, capsys):
    from popdata import write_population

    path, _ = write_population(tmp_path / "data", n_subjects=2)
    out = tmp_path / "run"
    printed, _ = _fit(["fit", MODEL, str(path), "--by", "subject", "--out", str(out), *QUICK], capsys)
    csv = path / "data.csv"
    assert f"data file:  {csv.resolve()} (sha256 {_sha(csv)})" in printed.out
    index = json.loads((out / "index.json").read_text())
    assert index["inputs"]["dataset"]["file_sha256"] == _sha(csv)
    assert index["inputs"]["priors"]["path"] == str(ROOT / "priors" / f"{MODEL}.toml")


def test_class_input_provenance_a_fit_of_a_dataframe_records_no_file():
    frame = pd.DataFrame({"normal_force [mN]": [200.0, 400, 800, 1600] * 3, "voltage [V]": [0.0] * 12,
                          "tangential_force [mN]": [101.0, 198, 405, 790] * 3})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = skinfit.fit(MODEL, skinfit.Dataset.from_frame(frame, model=MODEL), rng=1, ess_target=50, max_steps=300)
    assert fit.inputs["dataset"]["file"] is None and fit.inputs["dataset"]["origin"] == "not a file"
    assert "data file:  (not read from a file" in fit.report_text()


@pytest.mark.parametrize("kind", ["missing", "file", "empty", "models"])
def test_class_input_provenance_a_search_path_folder_that_is_not_one_is_an_error(user, tmp_path, capsys, monkeypatch,
                                                                                 kind):
    """--path or $SKINFIT_PATH naming a folder that does not exist (a typo), a file, a folder
    holding none of models/, priors/, datasets/ or references.toml, or the models/ folder itself:
    one line, exit 2, before any work (before: skipped in silence, the shipped files used)."""
    folder = tmp_path / "cards"
    if kind == "file":
        folder.write_text("x")
    elif kind == "empty":
        folder.mkdir()
    elif kind == "models":
        folder = tmp_path / "mine" / "models"
        folder.mkdir(parents=True)
        (folder / f"{MODEL}.toml").write_bytes((ROOT / "models" / f"{MODEL}.toml").read_bytes())
    why = {"missing": "no such folder", "file": "not a folder (expected one holding models/, priors/, datasets/)",
           "empty": "holds none of models/, priors/, datasets/, references.toml",
           "models": "holds none of models/, priors/, datasets/, references.toml (give the folder above it)"}[kind]
    out = tmp_path / "run"
    capsys.readouterr()
    assert main(["--path", str(folder), "fit", MODEL, DATA, "--out", str(out), *QUICK]) == 2
    assert capsys.readouterr().err.strip() == f"skinfit: error: --path: {folder}: {why}"
    assert not out.exists()
    monkeypatch.setenv("SKINFIT_PATH", str(folder))
    assert main(["models"]) == 2
    assert capsys.readouterr().err.strip() == f"skinfit: error: $SKINFIT_PATH: {folder}: {why}"
    with pytest.raises(skinfit.InputError, match="SKINFIT_PATH"):
        skinfit.load_model(MODEL)
