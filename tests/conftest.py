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
