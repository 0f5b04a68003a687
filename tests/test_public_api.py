"""Freeze the public API (DESIGN.md): a change here is a deliberate, visible decision."""

import skinfit


def test_public_names():
    assert sorted(skinfit.__all__) == sorted([
        "ConvergenceWarning", "Dataset", "Fit", "InputError", "Model", "PriorSet", "SupportWarning",
        "compare", "design", "evidence", "fit", "list_datasets", "list_models", "list_priors", "load_dataset", "load_fit",
        "load_model", "load_priors"])
    for name in skinfit.__all__:
        assert hasattr(skinfit, name)
