"""Fits split by group: one result per group, an index, seeds keyed by group label."""

import hashlib
import json
import warnings

import numpy as np
import pytest

import skinfit
from popdata import write_population
from skinfit.cli import main
from skinfit.groups import derive_seed, fit_by, group_labels, load_groups


def test_derive_seed_stable_and_keyed():
    a = derive_seed(5, "subject=S01")
    assert a == derive_seed(5, "subject=S01") and 0 <= a < 2**63
    assert len({a, derive_seed(6, "subject=S01"), derive_seed(5, "subject=S02"),
                derive_seed(5, "m", "d", "subject=S01")}) == 4
    # recomputed independently: numpy's SeedSequence with the sha256 words of the key as spawn key
    words = np.frombuffer(hashlib.sha256(b"m\x1fd").digest(), dtype="<u4")
    state = np.random.SeedSequence(7, spawn_key=tuple(int(w) for w in words)).generate_state(1, np.uint64)
    assert derive_seed(7, "m", "d") == int(state[0]) // 2


def test_cli_by_subject_one_result_per_group(tmp_path, capsys):
    path, truths = write_population(tmp_path, n_subjects=2, truths={"S01": 0.35, "S02": 0.65})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        code = main(["fit", "electroadhesion_coulomb", str(path), "--by", "subject", "--out", str(tmp_path / "run"),
                     "--seed", "11", "--ess", "100", "--quiet"])
    assert code == 0
    assert "subject=S02" in capsys.readouterr().out
    index = json.loads((tmp_path / "run" / "index.json").read_text())
    assert index["by"] == ["subject"] and index["seed"] == 11
    assert [g["group"] for g in index["groups"]] == ["subject=S01", "subject=S02"]
    fits = load_groups(tmp_path / "run")
    for g in index["groups"]:
        fit = fits[g["group"]]
        assert g["seed"] == derive_seed(11, g["group"]) == fit.idata.attrs["seed"]
        assert fit.idata.attrs["dataset_id"] == f"population[{g['group']}]" and g["rows"] == 4
        assert (tmp_path / "run" / g["path"]).parent.joinpath("summary.csv").exists()
        # each group's fit sees only its rows, and recovers its own friction coefficient
        mu = fit.idata["posterior"]["mu"].values
        truth = truths[g["group"].split("=")[1]]
        assert np.quantile(mu, 0.005) < truth < np.quantile(mu, 0.995)
    # a group's samples do not depend on which other groups exist
    ds = skinfit.load_dataset(path)
    one = ds.subset(ds.frame["subject"] == "S01", "only S01")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        fit_by("electroadhesion_coulomb", one, "subject", tmp_path / "one", seed=11, ess_target=100)
    alone = load_groups(tmp_path / "one")["subject=S01"]
    np.testing.assert_array_equal(alone.idata["posterior"]["mu"].values, fits["subject=S01"].idata["posterior"]["mu"].values)


def test_group_labels_and_errors(tmp_path):
    ds = skinfit.load_dataset("electroadhesion_synthetic")
    labels, levels = group_labels(ds, ["subject", "voltage"])
    assert levels[:2] == ["subject=S01,voltage=0", "subject=S01,voltage=25"] and len(levels) == 9
    assert len(labels) == len(ds)
    with pytest.raises(skinfit.InputError, match=r"--by: no column 'finger'.*declared groups: subject, voltage"):
        group_labels(ds, "finger")
    assert main(["fit", "electroadhesion_coulomb", "electroadhesion_synthetic", "--by", "finger",
                 "--out", str(tmp_path)]) == 2
