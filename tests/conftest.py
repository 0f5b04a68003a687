import os

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
