"""Fits split by group: one result per group, an index, seeds keyed by group label."""

import hashlib
import json
import warnings

import numpy as np
import pytest
from popdata import write_population

import skinfit
from skinfit.analysis.groups import derive_seed, fit_by, group_labels, load_groups
from skinfit.apps.cli import main


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


# ---- issue 21, class 2: results lost or mixed up; class 4: writes outside the output folder --------
ODD = {"a/b": 0.3, "a b": 0.5, "a_b": 0.7}  # one folder name under the old slug (a_b)


def _files(folder):
    return {p for p in folder.rglob("*") if p.is_file()}


@pytest.fixture(scope="module")
def odd_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("odd")
    data, _ = write_population(folder, truths=ODD, rows=6)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        fit_by("electroadhesion_coulomb", data, "subject", folder / "run", seed=4, ess_target=100)
    return folder, data


def test_class2_labels_differing_in_odd_characters_get_their_own_folders_and_fits(odd_run):
    folder, data = odd_run
    fits = load_groups(folder / "run")
    assert sorted(fits) == sorted(f"subject={s}" for s in ODD)
    assert len({p.parent for p in (folder / "run").glob("*/fit.nc")}) == 3
    rows = {}
    for line in (data / "data.csv").read_text().splitlines()[1:]:
        subject, _, _, ft = line.split(",")
        rows.setdefault(subject, []).append(float(ft) * 1e-3)
    for label, fit in fits.items():
        subject = label.split("=", 1)[1]
        assert fit.attrs["group"] == label
        # each fit was made from its own group's rows, read here from the CSV itself
        np.testing.assert_allclose(fit.idata["observed_data"]["tangential_force"].values, rows[subject], rtol=1e-12)


def test_class2_load_groups_refuses_a_fit_filed_under_another_label(odd_run, tmp_path):
    import shutil

    folder, _ = odd_run
    run = tmp_path / "run"
    shutil.copytree(folder / "run", run)
    index = json.loads((run / "index.json").read_text())
    a, b = (run / g["path"] for g in index["groups"][:2])
    a.rename(tmp_path / "swap.nc")
    b.rename(a)
    (tmp_path / "swap.nc").rename(b)
    with pytest.raises(skinfit.InputError,
                       match=r"listed for group 'subject=a/b'.*holds the fit of group 'subject=a b'"):
        load_groups(run)


def test_class1_load_groups_warns_when_the_data_changed_since(odd_run, tmp_path):
    import shutil

    folder, data = odd_run
    shutil.copytree(folder, tmp_path / "copy")
    index = json.loads((tmp_path / "copy" / "run" / "index.json").read_text())
    index["dataset_path"] = str(tmp_path / "copy" / data.name / "dataset.toml")
    (tmp_path / "copy" / "run" / "index.json").write_text(json.dumps(index))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # unchanged data: no warning
        assert len(load_groups(tmp_path / "copy" / "run")) == 3
    csv = tmp_path / "copy" / data.name / "data.csv"
    csv.write_text(csv.read_text().replace("a b,", "a c,"))
    with pytest.warns(UserWarning, match=r"the fits were made from .* with sha256 .*which now has"):
        load_groups(tmp_path / "copy" / "run")


def test_group_dir_is_a_name_distinct_per_exact_label():
    from skinfit.analysis.groups import group_dir
    from skinfit.io.campaign_file import NAME

    labels = ["a/b", "a b", "a_b", "A_B", "a=b", "a-b", "..", "../../x", "/etc/passwd", "", "é", "e"]
    names = [group_dir(x) for x in labels]
    assert len(set(names)) == len(labels) and len({n.lower() for n in names}) == len(labels)
    assert all(NAME.match(n) and len(n) <= 70 for n in names)
    assert group_dir("subject=S01").startswith("subject-S01-")


def test_class2_by_run_refuses_an_out_in_use(tmp_path, capsys):
    import os

    from skinfit.inference.checkpoint import CheckpointLock

    path, _ = write_population(tmp_path, n_subjects=1)
    out = tmp_path / "run"
    with CheckpointLock(out / "checkpoint.h5"):  # what a plain `skinfit fit --out run` holds
        code = main(["fit", "electroadhesion_coulomb", str(path), "--by", "subject", "--out", str(out), "--quiet"])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"skinfit: error: {out}: is in use by pid {os.getpid()} (lock .checkpoint.h5.lock); "
                   "wait for it to finish or use another --out")
    assert not (out / "index.json").exists()


def test_class2_strict_by_run_exits_3_when_a_group_warned(tmp_path):
    path, _ = write_population(tmp_path, n_subjects=1)
    argv = ["fit", "electroadhesion_coulomb", str(path), "--by", "subject", "--quiet", "--ess", "400",
            "--max-steps", "40", "--seed", "1"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        assert main(argv + ["--out", str(tmp_path / "a")]) == 0
        assert main(argv + ["--out", str(tmp_path / "b"), "--strict"]) == 3
    index = json.loads((tmp_path / "b" / "index.json").read_text())
    assert [g["converged"] for g in index["groups"]] == [False]  # the result is kept


def test_class4_group_labels_with_path_syntax_stay_inside_out(tmp_path):
    path, _ = write_population(tmp_path, truths={"../../x": 0.4, "/abs": 0.6}, rows=6)
    before = _files(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        fit_by("electroadhesion_coulomb", path, "subject", tmp_path / "deep" / "run", seed=2, ess_target=100)
    new = _files(tmp_path) - before
    assert new and all(p.is_relative_to(tmp_path / "deep" / "run") for p in new)
    assert sorted(load_groups(tmp_path / "deep" / "run")) == ["subject=../../x", "subject=/abs"]


def test_class1_report_check_names_fits_whose_data_changed(odd_run):
    from skinfit.analysis.groups import data_drift

    folder, data = odd_run
    fits = load_groups(folder / "run")
    items = [(label, f) for label, f in fits.items()]
    assert data_drift(items) == []  # the data are as fitted
    csv = data / "data.csv"
    original = csv.read_text()
    try:
        csv.write_text(original.replace("a b,", "a c,"))
        messages = data_drift(items)
    finally:
        csv.write_text(original)
    assert len(messages) == 3 and all("which now has" in m and "not of the current data" in m for m in messages)


def test_class_results_overwritten_an_out_holding_a_fit_is_refused_unless_overwrite(tmp_path, refused):
    """`skinfit fit --out DIR` (single or --by) into a folder holding a result: refused with one
    line naming --overwrite (and --resume where a checkpoint can be continued), saying whether
    the result there was made from other inputs, and not a byte of it changed; the other kind
    of run is refused even with --overwrite; --overwrite replaces. (Before: a rerun of the same
    inputs replaced the result without a word.)"""
    from skinfit.results.fit import load_fit

    path, _ = write_population(tmp_path / "a", n_subjects=2)
    other, _ = write_population(tmp_path / "b", n_subjects=2, truths={"S01": 0.2, "S02": 0.8})
    quick = ["--ess", "50", "--max-steps", "300", "--quiet"]
    single, run = tmp_path / "single", tmp_path / "run"
    tail = ": --overwrite to replace it{}, or give another --out (nothing was written)"
    resumable, by_run = tail.format(", --resume to continue from its checkpoint"), tail.format("")

    def holds(argv, out, what):
        refused(argv, out, f"holds {what}")

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        assert main(["fit", "electroadhesion_coulomb", str(path), "--out", str(single), "--seed", "1", *quick]) == 0
        holds(["fit", "electroadhesion_coulomb", str(path), "--out", str(single), "--seed", "2", *quick], single,
              "a fit of electroadhesion_coulomb on population, made from the same model card, prior file and data"
              + resumable)
        after = " than this fit of {} on population"
        holds(["fit", "electroadhesion", str(path), "--out", str(single), *quick], single,
              "a fit of electroadhesion_coulomb on population, made from another model"
              + after.format("electroadhesion") + resumable)
        holds(["fit", "electroadhesion_coulomb", str(other), "--out", str(single), *quick], single,
              "a fit of electroadhesion_coulomb on population, made from other data"
              + after.format("electroadhesion_coulomb") + resumable)
        holds(["fit", "electroadhesion_coulomb", str(path), "--by", "subject", "--out", str(single), "--overwrite",
               *quick], single, "a single fit (fit.nc): give the run by groups another --out (nothing was written)")
        assert main(["fit", "electroadhesion_coulomb", str(path), "--out", str(single), "--seed", "2", "--overwrite",
                     *quick]) == 0
        assert int(load_fit(single / "fit.nc").attrs["seed"]) == 2  # replaced, as asked

        assert main(["fit", "electroadhesion_coulomb", str(path), "--by", "subject", "--out", str(run), "--seed", "1",
                     *quick]) == 0
        holds(["fit", "electroadhesion_coulomb", str(path), "--by", "subject", "--out", str(run), *quick], run,
              "a run of electroadhesion_coulomb by subject, made from the same model card, prior file and data"
              + by_run)
        holds(["fit", "electroadhesion", str(path), "--by", "subject", "--out", str(run), *quick], run,
              "a run of electroadhesion_coulomb by subject, made from another model" + after.format("electroadhesion")
              + by_run)
        from skinfit.io.priors import load_priors

        (tmp_path / "priors.toml").write_text(load_priors("electroadhesion_coulomb").text + "\n# edited\n")
        holds(["fit", "electroadhesion_coulomb", str(path), "--by", "subject", "--priors",
               str(tmp_path / "priors.toml"), "--out", str(run), *quick], run,
              "a run of electroadhesion_coulomb by subject, made from another prior file"
              + after.format("electroadhesion_coulomb") + by_run)
        holds(["fit", "electroadhesion_coulomb", str(path), "--by", "voltage", "--out", str(run), *quick], run,
              "a run of electroadhesion_coulomb by subject, made from another grouping"
              + after.format("electroadhesion_coulomb") + by_run)
        holds(["fit", "electroadhesion_coulomb", str(path), "--out", str(run), "--overwrite", *quick], run,
              "a run by groups (index.json): give a single fit another --out (nothing was written)")
        assert main(["fit", "electroadhesion_coulomb", str(path), "--by", "subject", "--out", str(run), "--seed", "2",
                     "--overwrite", *quick]) == 0
        assert json.loads((run / "index.json").read_text())["seed"] == 2
        damaged = tmp_path / "damaged"
        damaged.mkdir()
        (damaged / "fit.nc").write_bytes(b"not a netCDF file")
        holds(["fit", "electroadhesion_coulomb", str(path), "--out", str(damaged), *quick], damaged,
              "a fit.nc that skinfit cannot read" + by_run)


def test_class_results_overwritten_an_unfinished_fit_is_continued_or_replaced_only_when_asked(tmp_path, refused):
    """A folder holding only the checkpoint of a fit that did not finish (killed): a plain rerun
    is refused (it would start afresh over hours of sampling), naming --resume and --overwrite;
    --resume of a finished fit without a checkpoint is refused rather than started afresh over it;
    a user's summary.csv in --out is not replaced without --overwrite."""
    from skinfit.inference.checkpoint import load_checkpoint

    out = tmp_path / "run"
    argv = ["fit", "electroadhesion_coulomb", "electroadhesion_synthetic", "--out", str(out), "--seed", "1",
            "--ess", "50", "--max-steps", "300", "--quiet"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        assert main(argv) == 0
    steps = load_checkpoint(out / "checkpoint.h5").iteration
    (out / "fit.nc").unlink()
    (out / "summary.csv").unlink()
    refused(argv, out, f"holds the checkpoint of a fit not finished (checkpoint.h5 at step {steps}): --overwrite to "
                       "replace it, --resume to continue from its checkpoint, or give another --out (nothing was written)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        assert main([*argv, "--resume"]) == 0
    (out / "checkpoint.h5").unlink()
    refused([*argv, "--resume"], out, "holds a finished fit (fit.nc) and no checkpoint to resume: --overwrite to "
                                      "replace it, or give another --out (nothing was written)")
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "summary.csv").write_text("my,table\n")
    refused([*argv[:3], "--out", str(mine), *argv[5:]], mine,
            "holds summary.csv (of an earlier fit): --overwrite to replace it, or give another --out (nothing was "
            "written)")


@pytest.mark.parametrize("text, why", [("[]", "not the index.json of `skinfit fit --by`"),
                                       ("3", "expected a `fit --by` index"), ('{"model": "x"}', "with 'groups'"),
                                       ("{not json", "not readable as JSON")])
def test_load_groups_refuses_an_index_that_is_not_a_run_by_groups(tmp_path, text, why):
    """A campaign's index, a JSON scalar, an index without groups or not JSON: one InputError
    naming the file (each was a TypeError, KeyError or JSONDecodeError traceback)."""
    (tmp_path / "index.json").write_text(text)
    with pytest.raises(skinfit.InputError, match=why) as refused:
        load_groups(tmp_path)
    assert str(refused.value).startswith(str(tmp_path / "index.json"))


def _two_subjects_one_impossible(folder):
    """The shipped electroadhesion data's first 40 rows as subjects S01 (20 rows) and S02 (20
    rows, its first with a zero normal force: every prior draw of the electroadhesion model is
    impossible there, so S02's MAP fails with MAPError)."""
    from pathlib import Path

    src = Path(skinfit.__file__).resolve().parents[1] / "datasets" / "electroadhesion_synthetic"
    out = folder / "two"
    out.mkdir()
    (out / "dataset.toml").write_text((src / "dataset.toml").read_text().replace(
        'id = "electroadhesion_synthetic"', 'id = "two"'))
    lines = (src / "data.csv").read_text().splitlines()[:41]
    for i in range(21, 41):
        lines[i] = "S02" + lines[i][3:]
    cells = lines[21].split(",")
    cells[2] = "0"
    lines[21] = ",".join(cells)
    (out / "data.csv").write_text("\n".join(lines) + "\n")
    return out


def test_failing_fit_never_touches_another_group_of_a_by_run(tmp_path, capsys):
    """Issue 39 point 8 for `skinfit fit --by`: S01 fits, S02's MAP fails. S01 is saved and
    listed; S02 is listed under 'failed' with its one-line error; the run exits 1; load_groups
    returns S01 and warns that S02 is left out; read_index counts it as not complete."""
    from skinfit.analysis.groups import read_index

    data = _two_subjects_one_impossible(tmp_path)
    run = tmp_path / "run"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        code = main(["fit", "electroadhesion", str(data), "--by", "subject", "--out", str(run), "--seed", "3",
                     "--ess", "40", "--max-steps", "600", "--quiet"])
    captured = capsys.readouterr()
    assert code == 1 and "1 of 2 group fit(s) failed" in captured.err
    index = json.loads((run / "index.json").read_text())
    assert [g["group"] for g in index["groups"]] == ["subject=S01"] and (run / index["groups"][0]["path"]).is_file()
    [failed] = index["failed"]
    assert failed["group"] == "subject=S02" and failed["error"].startswith("MAPError: ")
    assert "data row(s) 1 (normal_force = 0" in failed["error"] and "\n" not in failed["error"]
    assert "failed: MAPError: " in captured.out
    with pytest.warns(UserWarning, match=r"the fits of 1 group\(s\) failed and are left out \(subject=S02\)"):
        assert list(load_groups(run)) == ["subject=S01"]
    rows, skipped = read_index(run)
    assert [r["group"] for r in rows] == ["subject=S01"] and skipped == 1


def test_by_run_whose_every_group_fails_raises_the_first_error(tmp_path):
    """A bad option fails every group alike: the error itself (one line from the CLI), not a
    table of failures."""
    data, _ = write_population(tmp_path, n_subjects=2)
    with pytest.raises(skinfit.InputError) as info:
        fit_by("electroadhesion_coulomb", str(data), "subject", tmp_path / "run", seed=1, split={"mu": "nope"})
    assert "nope" in str(info.value)
    assert len(json.loads((tmp_path / "run" / "index.json").read_text())["failed"]) == 2
