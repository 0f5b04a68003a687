"""What `skinfit population` and the population / contrast entry points accept, by class:

* wrong or stale inputs used silently: a subject's fit replaced by another's, the same fit
  under two labels, fits of a data file edited since, a campaign's incomplete fits, a single
  fit's folder given as a run, a run being written while it is read;
* concurrent writers: two populations into one ``--out``;
* bad arguments: a one-line error naming the argument before any work, never a traceback;
* non-convergence: a loud message naming the hyper-parameters the data cannot determine and
  options the command has, exit status 3 under ``--strict``; every option any advice names
  exists.

Fixtures: three simulated Coulomb subjects at 0 V (tests/popdata.py), 4 presses each, so that
the friction coefficient mu is determined by each subject's data and E_star and d_air (seen
only through the voltage) are not.
"""

import contextlib
import io
import json
import os
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from popdata import write_population

import skinfit
from skinfit.analysis.contrasts import fit_contrasts, level_contrasts
from skinfit.analysis.groups import fit_by, load_groups
from skinfit.analysis.population.inputs import load_run
from skinfit.analysis.population.population import population
from skinfit.analysis.population.result import PopulationWarning, load_population
from skinfit.apps.cli import build_parser, main
from skinfit.errors import InputError

SOURCES = (*(f"analysis/population/{m}.py" for m in ("population", "checks", "hierarchical", "inputs", "result",
                                                     "reweight", "cache", "subjects")),
           "apps/cli/population.py", "analysis/groups.py", "analysis/contrasts.py")


@pytest.fixture(scope="module")
def run3(tmp_path_factory):
    """A `fit --by subject` run of 3 subjects (its folder and its data folder)."""
    folder = tmp_path_factory.mktemp("pop3")
    data, _ = write_population(folder, n_subjects=3, rows=4, seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        fit_by("electroadhesion_coulomb", str(data), "subject", folder / "run", seed=5, ess_target=100)
    return folder / "run", data


@pytest.fixture
def copy(run3, tmp_path):
    """A private copy of the run (its fits and index still name the module's data)."""
    run, data = run3
    shutil.copytree(run, tmp_path / "run")
    return tmp_path / "run", data


def _one_line_error(capsys, code):
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("skinfit: error: ") and "Traceback" not in err, err
    return lines[0]


def _paths(run):
    groups = json.loads((run / "index.json").read_text())["groups"]
    return {g["group"].split("=", 1)[1]: run / g["path"] for g in groups}


# ---- wrong or stale inputs ----------------------------------------------------------------
def test_class_wrong_fits_a_subject_whose_fit_was_replaced_by_anothers_is_refused(copy, capsys):
    run, _ = copy
    paths = _paths(run)
    shutil.copy(paths["S02"], paths["S01"])  # S01's file now holds S02's fit
    with pytest.raises(InputError, match=r"listed for subject S01 .* holds the fit of group 'subject=S02'"):
        load_run(run)
    code = main(["population", str(run), "--params", "mu", "--seed", "1", "--out", str(run.parent / "pop")])
    line = _one_line_error(capsys, code)
    assert "S01" in line and "subject=S02" in line
    assert not (run.parent / "pop").exists()  # nothing written


def test_class_stale_fits_of_an_edited_data_file_are_refused(run3, capsys, tmp_path):
    run, data = run3
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # as fitted: read without a word
        fits = load_groups(run)
        assert len(load_run(run)) == 3
    csv = data / "data.csv"
    original = csv.read_text()
    lines = original.splitlines()
    lines[2] = lines[2].rsplit(",", 1)[0] + ",123.0"  # one tangential force of S01 edited
    try:
        csv.write_text("\n".join(lines) + "\n")
        code = main(["population", str(run), "--params", "mu", "--seed", "1", "--out", str(tmp_path / "pop")])
        line = _one_line_error(capsys, code)
        assert "the fits of S01, S02, S03 were made from" in line and "which now has" in line and "stale" in line
        assert not (tmp_path / "pop").exists()
        # the Python entry points with the fits in memory: the same refusal, naming a subject
        with pytest.raises(InputError, match=r"subject subject=S01: fitted to .* which now has .* stale"):
            population(fits, "mu", rng=1)
        with pytest.raises(InputError, match=r"which now has .* stale"):
            fit_contrasts(fits, "mu", rng=1)
        with pytest.raises(InputError, match=r"which now has"), warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # load_groups' own warning (it reads for inspection)
            fit_contrasts(run, "mu", rng=1)
    finally:
        csv.write_text(original)


def test_class_wrong_fits_one_fit_counted_as_two_subjects_is_refused(run3):
    run, _ = run3
    fits = load_run(run)
    twice = {"A": fits["S01"], "B": fits["S01"], "C": fits["S02"]}
    with pytest.raises(InputError, match=r"subject B: holds the same fit as subject A"):
        population(twice, "mu", rng=1)
    with pytest.raises(InputError, match=r"subject B: holds the same fit as subject A"):
        fit_contrasts(twice, "mu", rng=1)
    # a list of fits keyed by their dataset: two of one dataset would silently become one
    with pytest.raises(InputError, match=r"fits 1 and 3 are both of .*give a mapping label -> Fit"):
        population([fits["S01"], fits["S02"], fits["S01"]], "mu", rng=1)


def test_class_wrong_inputs_a_campaigns_incomplete_fits_are_named_and_strict_exits_3(run3, tmp_path, capsys):
    run, _ = run3
    groups = json.loads((run / "index.json").read_text())["groups"]
    sha = json.loads((run / "index.json").read_text())["dataset_sha256"]
    rows = [{"model": "electroadhesion_coulomb", "dataset": "population", "group": g["group"], "status": "done",
             "path": str(run / g["path"]), "dataset_sha256": sha} for g in groups]
    rows.append({"model": "electroadhesion_coulomb", "dataset": "population", "group": "subject=S04",
                 "status": "failed", "path": str(run / "missing.nc"), "dataset_sha256": sha})
    (tmp_path / "index.json").write_text(json.dumps(rows))
    with pytest.warns(PopulationWarning, match=r"1 fit\(s\) of electroadhesion_coulomb that are not complete "
                                                r"\(S04 \(failed\)\): the population is of the other 3 subjects"):
        assert list(load_run(tmp_path)) == ["S01", "S02", "S03"]
    code = main(["population", str(tmp_path), "--params", "mu", "--seed", "1", "--strict",
                 "--out", str(tmp_path / "pop")])
    captured = capsys.readouterr()
    assert code == 3 and "WARNING: the campaign lists 1 fit(s)" in captured.out
    assert load_population(tmp_path / "pop" / "population.nc").subjects == ["S01", "S02", "S03"]  # kept


def test_class_wrong_inputs_groups_of_the_data_a_by_run_does_not_list_are_named(copy, capsys):
    """A `fit --by` killed after two of three subjects leaves an index of two: the population of
    those two says so (it is not the population of the data), and --strict exits 3."""
    run, _ = copy
    index = json.loads((run / "index.json").read_text())
    index["groups"] = index["groups"][:2]
    (run / "index.json").write_text(json.dumps(index))
    with pytest.warns(PopulationWarning, match=r"the run's data hold 1 group\(s\) its index does not list \(S03: "
                                                r"a `skinfit fit --by` that did not finish\?\): the population is of "
                                                r"the other 2 subjects only"):
        assert list(load_run(run)) == ["S01", "S02"]
    code = main(["population", str(run), "--params", "mu", "--seed", "1", "--strict", "--out", str(run / "pop")])
    assert code == 3 and "WARNING: the run's data hold 1 group(s)" in capsys.readouterr().out


def test_class_wrong_inputs_a_single_fits_folder_or_no_run_is_a_one_line_error(run3, tmp_path, capsys):
    run, _ = run3
    one = next(iter(_paths(run).values())).parent
    line = _one_line_error(capsys, main(["population", str(one), "--out", str(tmp_path / "p")]))
    assert "holds a single fit (fit.nc), not fits of several subjects" in line
    line = _one_line_error(capsys, main(["population", str(tmp_path / "nowhere"), "--out", str(tmp_path / "p")]))
    assert "no such run folder" in line
    (tmp_path / "index.json").write_text("{not json")
    line = _one_line_error(capsys, main(["population", str(tmp_path), "--out", str(tmp_path / "p")]))
    assert "not readable as JSON" in line
    assert not (tmp_path / "p").exists()


@pytest.mark.parametrize("damage, expected", [
    ("truncate", "not a readable skinfit result"),
    ("item", "row 1: expected a 'path' for each fit"),
    ("empty", "lists no completed fit: nothing to pool"),
])
def test_class_wrong_inputs_a_damaged_run_is_a_one_line_error(copy, capsys, damage, expected):
    run, _ = copy
    index = json.loads((run / "index.json").read_text())
    if damage == "truncate":
        fit = run / index["groups"][0]["path"]
        fit.write_bytes(fit.read_bytes()[:5000])
    elif damage == "item":
        index["groups"][0] = "subject=S01"
        (run / "index.json").write_text(json.dumps(index))
    else:
        (run / "index.json").write_text("[]")  # a campaign that has completed nothing
    line = _one_line_error(capsys, main(["population", str(run), "--out", str(run.parent / "p")]))
    assert expected in line


def test_class_concurrent_writers_a_run_being_written_is_not_read(run3, capsys):
    """`fit --by` rewrites index.json group by group: a population reading it meanwhile would see
    only the groups done so far. The population takes the reader's side of the writer's lock."""
    from skinfit.inference.checkpoint import CheckpointLock

    run, _ = run3
    out = run.parent / "pop_busy"
    with CheckpointLock(run / "checkpoint.h5"):  # what `skinfit fit --by --out RUN` holds while it runs
        line = _one_line_error(capsys, main(["population", str(run), "--params", "mu", "--out", str(out)]))
        with pytest.raises(InputError, match="is being written by pid"):
            load_groups(run)
    assert f"is being written by pid {os.getpid()}" in line and not out.exists()
    # readers do not exclude each other, and a writer may start once they are done
    with CheckpointLock(run / "checkpoint.h5", shared=True):
        assert len(load_run(run)) == 3
        with pytest.raises(InputError, match="in use by another skinfit process"):
            with CheckpointLock(run / "checkpoint.h5"):
                pass
    with CheckpointLock(run / "checkpoint.h5"):
        pass
    assert not (run / ".checkpoint.h5.lock").exists() and not (run / ".campaign.lock").exists()


def test_class_concurrent_writers_a_second_population_into_one_out_is_refused(run3, tmp_path, capsys):
    """Two `skinfit population` into one --out: the second is refused with one line while the
    first holds it (both had printed "written" and one result survived)."""
    run, _ = run3
    out = tmp_path / "pop"
    code = ("import sys, time; from skinfit.inference.checkpoint import CheckpointLock\n"
            f"with CheckpointLock({str(out / 'checkpoint.h5')!r}):\n"
            "    print('held', flush=True); time.sleep(60)\n")
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        line = _one_line_error(capsys, main(["population", str(run), "--params", "mu", "--seed", "1",
                                             "--out", str(out)]))
        assert line == (f"skinfit: error: {out}: is in use by pid {holder.pid} (lock .checkpoint.h5.lock); wait "
                        "for it to finish or use another --out")
        assert not (out / "population.nc").exists()
    finally:
        holder.kill()
        holder.wait()
    assert main(["population", str(run), "--params", "mu", "--seed", "1", "--out", str(out)]) == 0
    assert (out / "population.nc").exists() and not list(out.glob(".*.tmp"))


# ---- bad arguments ------------------------------------------------------------------------
@pytest.mark.parametrize("extra, expected", [
    (["--params", "mu,,E_star"], "--params: expected NAME[,NAME]"),
    (["--params", "mu,mu"], "--params: mu given twice"),
    (["--params", "slope"], "no sampled parameter 'slope' (sampled: mu, E_star, d_air, sigma)"),
    (["--params", "mu", "--family", "mu"], "--family: expected PARAMETER=FAMILY"),
    (["--params", "mu", "--family", "mu=gamma"], "--family: mu: unknown family 'gamma'"),
    (["--params", "mu", "--family", "mu=normal", "--family", "mu=lognormal"], "--family: mu given twice"),
    (["--params", "mu", "--family", "E_star=normal"], "'E_star' is not a population parameter"),
    (["--params", "mu", "--model", "other"], "no completed fit of model 'other'"),
    (["--params", "mu", "--max-sweeps", "300"], "--max-sweeps: expected more than the 300 burn-in sweeps"),
])
def test_class_bad_arguments_population_options_get_one_line_before_work(run3, tmp_path, capsys, extra,
                                                                         expected):
    run, _ = run3
    line = _one_line_error(capsys, main(["population", str(run), "--out", str(tmp_path / "p"), *extra]))
    assert expected in line
    assert not (tmp_path / "p").exists()


@pytest.mark.parametrize("extra", [["--seed", "-1"], ["--seed", str(2**64)], ["--seed", "x"],
                                   ["--max-sweeps", "0"], ["--method", "nuts"]])
def test_class_bad_arguments_out_of_range_values_are_usage_errors(run3, capsys, extra):
    run, _ = run3
    with pytest.raises(SystemExit) as exc:
        main(["population", str(run), *extra])
    assert exc.value.code == 2 and "Traceback" not in capsys.readouterr().err


def test_class_bad_arguments_an_out_that_is_a_file_or_the_run_itself(run3, tmp_path, capsys):
    run, _ = run3
    (tmp_path / "afile").write_text("mine")
    line = _one_line_error(capsys, main(["population", str(run), "--out", str(tmp_path / "afile")]))
    assert "is a file: --out names the folder" in line and (tmp_path / "afile").read_text() == "mine"
    line = _one_line_error(capsys, main(["population", str(run), "--out", str(run)]))
    assert "is the run's own folder" in line


@pytest.mark.parametrize("kwargs, expected", [
    ({"parameters": []}, "parameters: expected at least one parameter name"),
    ({"parameters": ["mu", "mu"]}, "mu named twice"),
    ({"parameters": [1]}, "expected parameter names (got 1)"),
    ({"family": "gamma"}, "unknown family 'gamma'"),
    ({"family": {"mu": "cauchy"}}, "mu: unknown family 'cauchy'"),
    ({"family": 3}, "expected a family or a mapping"),
    ({"method": "nuts"}, "unknown method 'nuts'"),
    ({"rng": -1}, "rng: expected a seed"),
    ({"rng": 1.5}, "rng: expected a seed"),
    ({"chains": 1}, "chains: expected a whole number in 2 .. 1000"),
    ({"ess_target": 0}, "ess_target: expected a number > 0"),
    ({"rhat_max": 0.99}, "rhat_max: expected a number > 1"),
    ({"max_sweeps": 300}, "max_sweeps: expected a whole number >= 301"),
    ({"burn": -1}, "burn: expected a whole number >= 0"),
    ({"min_contraction": 2}, "min_contraction: expected a number >= 0 and <= 1"),
    ({"correlated": "yes"}, "correlated: expected True or False"),
    ({"n_draws": 0}, "n_draws: expected a whole number >= 10"),
])
def test_class_bad_arguments_population_python_arguments_get_one_line(run3, kwargs, expected):
    run, _ = run3
    fits = load_run(run)
    kwargs = {"parameters": "mu", "rng": 1, **kwargs}
    with pytest.raises(InputError, match=re.escape(expected)) as exc:
        population(fits, **kwargs)
    assert "\n" not in str(exc.value)


def test_class_bad_arguments_population_cache_fits_and_results(run3, tmp_path):
    run, _ = run3
    fits = load_run(run)
    with pytest.raises(InputError, match="is a folder: expected the path of the population cache file"):
        population(fits, "mu", rng=1, cache=tmp_path)
    with pytest.raises(InputError, match=r"item 2 is a str, not a Fit"):
        population([fits["S01"], "S02.nc"], "mu")
    with pytest.raises(InputError, match=r"expected a run folder, a mapping label -> Fit or a list of Fits"):
        population(42, "mu")
    with pytest.raises(InputError, match="no such population file"):
        load_population(tmp_path / "none.nc")
    (tmp_path / "junk.nc").write_bytes(b"\0" * 64)
    with pytest.raises(InputError, match="not a readable skinfit population result"):
        load_population(tmp_path / "junk.nc")


def test_class_bad_arguments_contrasts_and_effects_get_one_line(run3, cli_mu):
    run, _ = run3
    fits = load_run(run)
    for kwargs, expected in [({"prob": 1.5}, "prob: expected an interval probability"),
                             ({"prob": 0}, "prob: expected an interval probability"),
                             ({"rng": -3}, "rng: expected a seed >= 0"),
                             ({"parameter": 7}, "parameter: expected the name of a sampled parameter")]:
        with pytest.raises(InputError, match=re.escape(expected)):
            fit_contrasts(fits, **{"parameter": "mu", **kwargs})
    with pytest.raises(InputError, match="expected a mapping label -> Fit or a `fit --by` run folder"):
        fit_contrasts([fits["S01"], fits["S02"]], "mu")
    with pytest.raises(InputError, match="prob: expected an interval probability"):
        level_contrasts(fits["S01"], "mu", prob=95)
    result = cli_mu
    # a log-normal population has no mass at or below 0: the question "below 0?" was answered
    # silently as "median below 1?" before
    with pytest.raises(InputError, match=r"mu has a log-normal population .* expected a reference > 0"):
        result.effect("mu", reference=0.0)
    with pytest.raises(InputError, match="prob: expected an interval probability"):
        result.summary(prob=95)
    with pytest.raises(InputError, match="no population parameter 'sigma'"):
        result.contrast("mu", "sigma")


@pytest.fixture(scope="module")
def cli_mu(run3):
    run, _ = run3
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PopulationWarning)
        return population(load_run(run), "mu", rng=1)


# ---- non-convergence ----------------------------------------------------------------------
def test_class_non_convergence_names_the_undetermined_hyper_parameters_and_strict_exits_3(run3, tmp_path,
                                                                                          capsys):
    """E_star and d_air enter the Coulomb model only through the voltage, which is 0 here: no
    subject's data move their prior, so their population mean and sd rest on the hyper-priors.
    Stopped after 350 sweeps (not converged), the message names them and says why, and the
    options it names exist and run."""
    run, _ = run3
    out = tmp_path / "pop"
    code = main(["population", str(run), "--seed", "1", "--max-sweeps", "350", "--strict", "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 3
    (warning,) = [ln for ln in captured.out.splitlines() if "not converged" in ln]
    assert warning.startswith("WARNING: hyper-posterior not converged after 350 sweeps")
    assert "The data cannot determine the population of E_star, d_air: each of the 3 subjects' own fits " \
           "barely moves their prior" in warning
    assert "(2 degrees of freedom for a sd)" in warning
    assert re.search(r"E_star: contraction -?\d\.\d\d--?\d\.\d\d, tau 90% interval", warning)
    assert "Rerun with --params mu (Python: parameters=['mu'])" in warning
    sweeps = int(re.search(r"--max-sweeps (\d+) \(Python: max_sweeps=\1;", warning).group(1))
    assert sweeps > 350
    assert "NOT converged" in captured.err and "--strict" not in captured.err
    assert (out / "population.nc").exists()  # the result is kept
    # without --strict: exit 0, still said on stderr
    assert main(["population", str(run), "--seed", "1", "--max-sweeps", "350", "--out", str(out), "--overwrite"]) == 0
    assert "NOT converged" in capsys.readouterr().err
    # the advice runs: mu alone, every subject's data determine it
    assert main(["population", str(run), "--seed", "1", "--params", "mu", "--strict", "--out", str(out), "--overwrite"]) == 0
    assert "converged: yes" in capsys.readouterr().out


def test_class_advice_every_option_named_in_advice_exists():
    """Every `--option` that population, its checks, the Gibbs sampler, groups and contrasts
    name in a message is an option of a skinfit command (a "larger max_sweeps" the CLI lacked)."""
    commands = re.search(r"\{([a-z,]+)\}", build_parser().format_help()).group(1).split(",")
    options = set()
    for command in commands:
        with pytest.raises(SystemExit), contextlib.redirect_stdout(io.StringIO()) as text:
            build_parser().parse_args([command, "--help"])
        options |= set(re.findall(r"(?<![\w-])--[a-z][a-z-]*[a-z]", text.getvalue()))
    assert "population" in commands and "--max-sweeps" in options
    named = set()
    for name in SOURCES:
        text = (Path(skinfit.__file__).parent / name).read_text()
        named |= set(re.findall(r"(?<![\w-])--[a-z][a-z-]*[a-z]", text))
    assert named - options == set(), named - options
    assert {"--max-sweeps", "--strict", "--params"} <= named


# ---- the sampler's proposals in product / shift / shear coordinates ----------------------
def test_class_non_convergence_the_proposal_maps_the_population_through_product_and_shear_coordinates():
    """electroadhesion samples beta0 as X = beta0 tau0 E_star^(-2/3) (product), d_air as
    log(d_air + c) (shift) and phi as log phi - offset(d_air) (shear): the population of
    u = log theta enters the subjects' proposals through du/dz, whose beta0 row is, from the
    card, d log beta0 = dX / X - d log tau0 + 2/3 d log E_star (the old proposal treated z as
    log theta or theta and accepted 0.5% of a 3-subject population's draws)."""
    from skinfit.analysis.population.hierarchical import Spec
    from skinfit.analysis.population.subjects import Subjects
    from skinfit.io.data import load_dataset
    from skinfit.io.models import load_model
    from skinfit.io.priors import load_priors
    from skinfit.posterior import Posterior

    post = Posterior(load_model("electroadhesion"), load_priors("electroadhesion"),
                     load_dataset("electroadhesion_synthetic"))
    rng = np.random.default_rng(0)
    z = post.to_z(post.sample_prior(400, rng))
    names = list(post.names)
    pop = [names.index(n) for n in ("E_star", "tau0", "d_air", "beta0", "phi", "eta", "alpha")]
    spec = Spec(pop, [True] * 7, [False] * 7, np.zeros(7), np.ones(7), False)
    subs = Subjects([post], [(z.mean(axis=0), np.cov(z.T))], spec)
    J, zbar = subs.J[0], z.mean(axis=0)
    theta = post.to_theta(zbar[None])[0]
    row = J[3]  # beta0
    assert row[names.index("beta0")] == pytest.approx(1 / zbar[names.index("beta0")], rel=1e-6)
    assert row[names.index("tau0")] == pytest.approx(-1.0, rel=1e-6)
    assert row[names.index("E_star")] == pytest.approx(2 / 3, rel=1e-6)
    # d_air: u = log d_air, z = log(d_air + c): du/dz = (d_air + c) / d_air
    c = np.exp(zbar[names.index("d_air")]) - theta[names.index("d_air")]
    assert J[2, names.index("d_air")] == pytest.approx((theta[names.index("d_air")] + c)
                                                       / theta[names.index("d_air")], rel=1e-5)
    # phi: u = z_phi + offset(d_air): unit slope in z_phi, a cross term in d_air
    assert J[4, names.index("phi")] == pytest.approx(1.0, rel=1e-6) and J[4, names.index("d_air")] != 0
    # the location and scale moves hold the other slots fixed in z: valid while none of them
    # depends on a population slot (the noise scale; beta0 with tau0 outside; not tau0 with
    # beta0 outside, whose natural value is X / (tau0 E_star^(-2/3)))
    assert subs.separable

    def separable(names_in):
        idx = [names.index(n) for n in names_in]
        k = len(idx)
        return Subjects([post], [(z.mean(axis=0), np.cov(z.T))],
                         Spec(idx, [True] * k, [False] * k, np.zeros(k), np.ones(k), False)).separable

    assert separable(["beta0"]) and not separable(["tau0"]) and not separable(["d_air"])
