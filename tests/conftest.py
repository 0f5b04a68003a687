import ast
import os
from pathlib import Path

import numpy as np
import pytest

#: Fixed seed, overridable from the environment (SKINFIT_TEST_SEED) to probe for flakes.
SEED = int(os.environ.get("SKINFIT_TEST_SEED", "12345"))


@pytest.fixture
def rng():
    return np.random.default_rng(SEED)


@pytest.fixture(scope="session")
def ea_fit():
    """The shipped electroadhesion fit (seed 1), shared by the tests that read it."""
    import skinfit

    return skinfit.fit("electroadhesion", "electroadhesion_synthetic", rng=1)


@pytest.fixture
def no_figures(monkeypatch):
    """Reports written without drawing their figures (each figure job reported as drawn), for
    tests of what a report does with its folder, tables and text."""
    from skinfit.report import html as report

    def drawn(fits, jobs, figdir, workers=None, meanwhile=None):
        return [None] * (len(jobs) + len(meanwhile() if meanwhile is not None else []))

    monkeypatch.setattr(report, "render_figures", drawn)


@pytest.fixture
def refused(capsys):
    """``refused(argv, where, message)``: the CLI run on ``argv`` exits 2 with exactly the one
    line ``skinfit: error: WHERE: MESSAGE`` on stderr, and not a byte of a file under ``where``
    changed (nor a file added or removed)."""
    from skinfit.apps.cli import main

    def check(argv, where, message):
        files = {p: p.read_bytes() for p in where.rglob("*") if p.is_file()}
        capsys.readouterr()
        assert main(argv) == 2
        assert capsys.readouterr().err.strip() == f"skinfit: error: {where}: {message}"
        assert {p: p.read_bytes() for p in where.rglob("*") if p.is_file()} == files

    return check


#: Files whose tests exercise the mechanics around the numbers (figures drawn and laid out,
#: reports in a browser, processes killed and resumed, campaigns, the demo): marked
#: ``mechanics``, left out of the default run (the README's test command) and run by .ci/run.
MECHANICS = {"test_browser.py", "test_campaign.py", "test_checkpoint.py", "test_demo.py", "test_figure_files.py",
             "test_figure_folder.py", "test_own_files.py", "test_plots.py", "test_report.py", "test_report_groups.py", "test_soak.py"}

#: Single tests of the same kind in files otherwise of the default run: whole command-line runs
#: in new processes, caches and overwrite refusals on disk (10-25 s each on 2 cores).
MECHANICS_TESTS = {
    ("test_outputs.py", "test_class_results_overwritten_population_out"),
    ("test_population.py", "test_cli_writes_tree_tables_and_states_the_family"),
    ("test_population.py", "test_a_population_records_its_fits_by_content_and_its_seed"),
    ("test_population.py", "test_a_cached_population_keeps_its_diagnostics"),
    ("test_startup.py", "test_skinfit_fit_in_a_new_process_saves_every_group"),
    ("test_startup.py", "test_a_saved_fits_figures_import_what_each_needs"),
}


#: Long correctness checks (samplers against quadrature and closed forms, SBC, recovery on
#: shipped data, memory budgets): (file, test) marked ``heavy``, run by .ci/run beside the default run.
HEAVY = {
    ("test_population.py", "test_gibbs_and_reweighting_agree_on_the_hyper_posterior"),
    ("test_population.py", "test_hyper_truths_in_95_intervals_and_shrinkage_helps"),
    ("test_population.py", "test_gibbs_with_its_non_centred_moves_matches_quadrature"),
    ("test_population.py", "test_small_sbc_passes_and_its_negative_control_fails"),
    ("test_population.py", "test_correlated_population_gives_valid_correlations"),
    ("test_population.py", "test_a_cached_population_is_the_same_result_and_only_for_the_same_inputs"),
    ("test_population.py", "test_shrunk_estimates_beat_separate_fits_with_two_presses"),
    ("test_sbc.py", "test_small_sbc_is_uniform"),
    ("test_sbc.py", "test_wrong_prior_is_flagged"),
    ("test_sbc.py", "test_same_seed_same_ranks_whatever_the_processes"),
    ("test_sbc.py", "test_fork_from_a_threaded_process_never_happens_simulations_run_here"),
    ("test_physics_wavy.py", "test_recovery_on_the_shipped_dataset"),
    ("test_evidence.py", "test_nested_matches_closed_form"),
    ("test_moves.py", "test_negative_control_emcee_released_snooker_is_biased"),
    ("test_moves.py", "test_independence_move_samples_gaussian"),
    ("test_moves.py", "test_negative_control_independence_move_without_hastings_factor_is_biased"),
    ("test_errors_resources.py", "test_class5_pointwise_groups_thinned_to_the_memory_budget"),
    ("test_errors_resources.py", "test_class6_full_tmpfs_gives_one_line_and_no_crash"),
    ("test_design.py", "test_skinfit_report_shows_a_design_folder_as_a_section"),
}


def pytest_configure(config):
    """Every (file, test) named by MECHANICS_TESTS and HEAVY is a test function of that file: a
    renamed or removed test would otherwise return to the default run unnoticed."""
    here = Path(__file__).parent
    missing = []
    for file, name in sorted(MECHANICS_TESTS | HEAVY):
        tree = ast.parse((here / file).read_text(encoding="utf-8")) if (here / file).is_file() else None
        defined = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)} if tree else set()
        if name not in defined:
            missing.append(f"{file}::{name}")
    if missing:
        raise pytest.UsageError(f"tests/conftest.py names tests that do not exist: {', '.join(missing)}")


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.name in MECHANICS or (item.path.name, getattr(item, "originalname", item.name)) in MECHANICS_TESTS:
            item.add_marker(pytest.mark.mechanics)
        if (item.path.name, getattr(item, "originalname", item.name)) in HEAVY:
            item.add_marker(pytest.mark.heavy)
