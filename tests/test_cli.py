"""The command line is a thin layer: listings, fit to a run directory, clear errors."""

import json
import warnings

import pytest

import skinfit
from skinfit.apps.cli import main


def test_listings(capsys):
    assert main(["models", "--json"]) == 0
    models = {m["id"]: m for m in json.loads(capsys.readouterr().out)}
    assert "tangential_force [N]" in models["electroadhesion"]["observables"]
    assert main(["priors", "electroadhesion"]) == 0
    out = capsys.readouterr().out
    assert 'E_star [Pa]: dist = "lognormal", median = 40000.0, sigma = 0.6, bounds = [2000.0, 100000.0]' in out
    assert "in Python: skinfit.truncate(st.lognorm(s=0.6, scale=40000.0), 2000.0, 100000.0)" in out
    assert ("source: Basdogan, Sormoli & Sirin (2020), \u201cModeling Sliding Friction Between Human Finger and "
            "Touchscreen Under Electroadhesion\u201d, IEEE Transactions on Haptics, Table I") in out
    assert main(["datasets"]) == 0
    assert "electroadhesion_synthetic (simulated, 216 rows" in capsys.readouterr().out


def test_fit_writes_run_directory(tmp_path, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = main(["fit", "electroadhesion_coulomb", "electroadhesion_synthetic", "--out", str(tmp_path / "r"),
                     "--seed", "3", "--quiet"])
    assert code == 0
    out = capsys.readouterr().out
    assert "hdi_3%" in out and "ess_tail" in out and "wall time" in out
    fit = skinfit.load_fit(tmp_path / "r" / "fit.nc")
    assert fit.idata.attrs["seed"] == 3 and (tmp_path / "r" / "summary.csv").exists()


def test_errors_exit_2_with_message(capsys, tmp_path):
    assert main(["fit", "nope", "electroadhesion_synthetic", "--out", str(tmp_path)]) == 2
    assert "no such model" in capsys.readouterr().err
    assert main(["fit", "electroadhesion", "electroadhesion_synthetic", "--out", str(tmp_path), "--split", "alpha"]) == 2
    assert "expected PARAMETER=COLUMN" in capsys.readouterr().err


def test_help_lists_commands(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for cmd in ["models", "priors", "datasets", "fit", "demo"]:
        assert cmd in out
