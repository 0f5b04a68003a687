"""Whether a fit's model card is the shipped one, unchanged, with skinfit's own physics
(:func:`skinfit.io.shipped.shipped_physics`): what the population cache keys on."""

from skinfit.io.shipped import shipped_physics
from skinfit.results.fit import load_fit


def test_only_unchanged_shipped_models_are_shipped_physics(ea_fit, tmp_path):
    assert shipped_physics(ea_fit.model_id, ea_fit.attrs["model_sha256"])
    ea_fit.save(tmp_path / "fit.nc")
    edited = load_fit(tmp_path / "fit.nc")
    edited.idata.attrs["model_sha256"] = "0" * 64  # fitted with another card of that name
    assert not shipped_physics(edited.model_id, edited.attrs["model_sha256"])
    assert not shipped_physics("no_such_model", ea_fit.attrs["model_sha256"])


def test_shipped_physics_wherever_the_process_runs(ea_fit, tmp_path, monkeypatch):
    """The shipped card is recognised by its location, not by a path relative to the
    working folder (a report run from any folder)."""
    monkeypatch.chdir(tmp_path)
    assert shipped_physics(ea_fit.model_id, ea_fit.attrs["model_sha256"])
