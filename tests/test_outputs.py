"""Class: results silently overwritten or lost. Every command that writes a result folder
refuses, before any work and with one line naming --overwrite, a folder that holds its earlier
results (or files of the names it writes), and replaces them only when asked. (``skinfit fit``
single and --by: tests/test_groups.py; a report rewrites its own folder by design:
tests/test_report.py.)"""

import shutil
import warnings

import pytest
from popdata import write_population

import skinfit
from skinfit.apps.campaign import check_campaign_out, load_campaign
from skinfit.apps.cli import main

QUICK = ["--ess", "50", "--max-steps", "300", "--quiet"]


def _earlier(out, command):
    return (f"holds the results of an earlier {command} ({{}}): --overwrite to replace them, or give another --out "
            "(nothing was written)")


def test_class_results_overwritten_design_out(tmp_path, refused):
    """`skinfit design --out DIR` twice: the second refused before any Monte Carlo; --overwrite
    replaces; a folder of the user's holding a plan.csv is refused too."""
    grid = tmp_path / "grid.toml"
    grid.write_text('[grid.normal_force]\nunit = "mN"\nvalues = [200, 1000, 2000]\n'
                    '[grid.voltage]\nunit = "V"\nvalues = [0, 200]\n')
    out = tmp_path / "d"
    argv = ["design", "electroadhesion", "--candidates", str(grid), "--n", "3", "--outer", "30", "--inner", "30",
            "--sigma", "0.02", "--seed", "4", "--out", str(out)]
    assert main(argv) == 0
    refused(argv, out, _earlier(out, "skinfit design").format(
        "plan.csv, candidates.csv, baseline.csv, comparison.csv and 3 more"))
    assert main([*argv[:-4], "--seed", "5", "--out", str(out), "--overwrite"]) == 0
    assert '"seed": 5' in (out / "design.json").read_text()
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "plan.csv").write_text("my own plan\n")
    refused([*argv[:-1], str(mine)], mine, _earlier(mine, "skinfit design").format("plan.csv"))


def test_class_results_overwritten_population_out(tmp_path, refused):
    """`skinfit population RUN` twice (its default --out RUN/population): the second refused
    before sampling; --overwrite replaces."""
    from skinfit.analysis.groups import fit_by

    path, _ = write_population(tmp_path / "data", n_subjects=3)
    run = tmp_path / "run"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        fit_by("electroadhesion_coulomb", str(path), "subject", run, seed=2, ess_target=60, max_steps=600)
    argv = ["population", str(run), "--params", "mu", "--seed", "1"]
    assert main(argv) == 0
    before = (run / "population" / "population.nc").read_bytes()
    refused([*argv[:-1], "2"], run / "population", _earlier(run / "population", "skinfit population").format(
        "population.nc, population_summary.csv, population_subjects.csv, population_effects.csv"))
    assert (run / "population" / "population.nc").read_bytes() == before
    assert main([*argv[:-1], "2", "--overwrite"]) == 0
    assert (run / "population" / "population.nc").read_bytes() != before


def test_class_results_overwritten_sbc_out(tmp_path, refused):
    """`skinfit sbc --out DIR` twice: the second refused before the simulations; --overwrite replaces."""
    out = tmp_path / "sbc"
    argv = ["sbc", "electroadhesion_coulomb", "--n-sims", "2", "--draws", "3", "--rows", "12", "--ess", "20",
            "--max-steps", "200", "--seed", "1", "--out", str(out)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        assert main(argv) == 0
        refused(argv, out, _earlier(out, "skinfit sbc").format("ranks.csv, truth.csv, sbc.csv, runs.csv and 3 more"))
        assert main([*argv, "--overwrite"]) == 0


def test_class_results_overwritten_a_campaign_never_replaces_an_index_it_did_not_write(tmp_path):
    """A campaign's out holding an index.csv and no index.json (no campaign wrote it): refused."""
    data, _ = write_population(tmp_path, n_subjects=2)
    path = tmp_path / "c.toml"
    path.write_text(f'schema_version = 1\nseed = 3\nout = "out"\nmodels = ["electroadhesion_coulomb"]\n'
                    f'datasets = ["{data.name}"]\n')
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "index.csv").write_text("my,index\n")
    with pytest.raises(skinfit.InputError, match="holds an index.csv that no campaign wrote"):
        check_campaign_out(load_campaign(path))


def test_class_results_overwritten_a_csv_fits_card_folder(tmp_path, refused):
    """`skinfit fit MODEL data.csv --out OUT` writes the CSV's card to OUT/dataset: a dataset
    folder there (the user's, or an earlier run's) is refused without --overwrite; the rerun from
    that written card's own data.csv with --overwrite works (it is not copied onto itself)."""
    csv = tmp_path / "data.csv"
    csv.write_text("normal_force [mN],voltage [V],tangential_force [mN]\n"
                   + "".join(f"{200 + 100 * i},{50 * (i % 3)},{(200 + 100 * i) * 0.5 + 3 * (-1) ** i}\n"
                             for i in range(12)))
    out = tmp_path / "out"
    (out / "dataset").mkdir(parents=True)
    (out / "dataset" / "notes.txt").write_text("mine")
    argv = ["fit", "electroadhesion_coulomb", str(csv), "--out", str(out), "--seed", "1", *QUICK]
    refused(argv, out, "holds dataset (of an earlier fit): --overwrite to replace it, or give another --out "
                       "(nothing was written)")
    shutil.rmtree(out / "dataset")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        assert main(argv) == 0
        again = ["fit", "electroadhesion_coulomb", str(out / "dataset" / "data.csv"), "--out", str(out), "--seed", "1",
                 "--overwrite", *QUICK]
        assert main(again) == 0
    assert (out / "dataset" / "data.csv").read_text() == csv.read_text()
