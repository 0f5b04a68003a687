"""Covariate-only quantities cached by value (skinfit/physics/_cache.py): a covariate array
changed in place is never served a stale result, and what the cache holds cannot be changed."""

import numpy as np
import pytest

import skinfit
from skinfit.physics import textured, ultrasonic
from skinfit.posterior import Posterior


def _setup(model, data, rng):
    post = Posterior(skinfit.load_model(model), skinfit.load_priors(model), skinfit.load_dataset(data))
    return {c: v.copy() for c, v in post.x.items()}, post.unpack(post.sample_prior(8, rng)), post.constants


@pytest.mark.parametrize("module, model, data, column, cached", [
    (textured, "textured_surface", "textured_synthetic", "normal_force", "_terms"),
    (ultrasonic, "ultrasonic", "ultrasonic_synthetic", "amplitude_pp", "_nodes"),
])
def test_in_place_change_of_a_covariate_is_seen(module, model, data, column, cached, rng):
    x, p, c = _setup(model, data, rng)
    f = getattr(module, model)
    before = f(p, x, c)[0]["friction_coefficient"].copy()
    x[column] *= 1.5  # same array object, new values
    after = f(p, x, c)[0]["friction_coefficient"]
    getattr(module, cached).cache_clear()
    fresh = f(p, x, c)[0]["friction_coefficient"]
    assert np.array_equal(after, fresh)
    assert not np.allclose(after, before)


def test_cached_arrays_are_read_only(rng):
    x, p, c = _setup("textured_surface", "textured_synthetic", rng)
    state = textured.contact_state(p, x, c)
    with pytest.raises(ValueError, match="read-only"):
        state["ok"][0] = False
    x = _setup("ultrasonic", "ultrasonic_synthetic", rng)[0]
    inv_v = ultrasonic._nodes(*ultrasonic._rows(x), scalars=(ultrasonic.PHASES, False))[0]
    with pytest.raises(ValueError, match="read-only"):
        inv_v[0] = 0.0
