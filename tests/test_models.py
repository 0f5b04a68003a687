"""Every model card: loads, resolves through the registry, matches its function and priors."""

from pathlib import Path

import numpy as np
import pytest

import skinfit

ROOT = Path(skinfit.__file__).resolve().parents[1]
CARDS = sorted(p.stem for p in (ROOT / "models").glob("*.toml"))


@pytest.mark.parametrize("card", CARDS)
def test_card_matches_function_and_priors(card, rng):
    model = skinfit.load_model(card)
    assert model.id == card
    priors = skinfit.load_priors(card)
    for variant in model.variants:
        assert variant in CARDS, f"{card} names unknown variant {variant}"
    # a prior draw of k parameter vectors evaluated on synthetic covariates gives (k, n)
    k, n = 6, 11
    params = {p: priors[p].rvs(k, rng) for p in model.parameter_names}
    cov = {c.name: np.linspace(0.5, 1.5, n) for c in model.covariates}
    y, ok = model.evaluate({p: v[:, None] for p, v in params.items()}, cov)
    assert set(y) == set(model.observable_names)
    for arr in y.values():  # (k, n); a model without parameters may return one row for all
        assert arr.shape == ((k, n) if model.parameter_names else (1, n)) and np.all(np.isfinite(arr))
    assert np.broadcast_to(ok, (k, n)).shape == (k, n)


def test_card_may_only_name_registry_functions(tmp_path):
    text = (ROOT / "models" / "electroadhesion.toml").read_text()
    for ref, match in [("os:system", "'os:system' is not a registered forward function"),
                       ("skinfit.physics.electroadhesion:np", "'skinfit.physics.electroadhesion:np' is not a registered"),
                       ("skinfit.physics.nothere:f", "'skinfit.physics.nothere:f' is not a registered")]:
        bad = tmp_path / "bad.toml"
        bad.write_text(text.replace('"skinfit.physics.electroadhesion:electroadhesion"', f'"{ref}"'))
        with pytest.raises(skinfit.InputError, match=match):
            skinfit.load_model(str(bad))


def test_unknown_noise_and_missing_field(tmp_path):
    text = (ROOT / "models" / "electroadhesion.toml").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('noise = "normal"', 'noise = "laplace"'))
    with pytest.raises(skinfit.InputError, match=r"observables\[0\].noise: unknown noise model 'laplace'"):
        skinfit.load_model(str(bad))
    bad.write_text(text.replace('title = ', 'name_of_it = '))
    with pytest.raises(skinfit.InputError, match="title: missing required field"):
        skinfit.load_model(str(bad))


def test_unknown_model_lists_known():
    with pytest.raises(skinfit.InputError, match="no such model .*electroadhesion"):
        skinfit.load_model("nope")


def test_missing_shipped_cards_say_where_they_were_looked_for(tmp_path, monkeypatch):
    """With nothing on the search path (no shipped files, an empty user folder) the error names
    every folder searched and where it came from, not an empty list."""
    import skinfit.io.paths
    import skinfit.io.registry

    monkeypatch.setattr(skinfit.io.paths, "shipped_root", lambda: None)
    monkeypatch.setattr(skinfit.io.registry, "plugin_folders", list)
    monkeypatch.setattr(skinfit.io.paths, "user_root", lambda: tmp_path / "user")
    monkeypatch.delenv("SKINFIT_PATH", raising=False)
    for load, kind in ((skinfit.load_model, "models"), (skinfit.load_priors, "priors"),
                       (skinfit.load_dataset, "datasets")):
        with pytest.raises(skinfit.InputError, match=f"known: none; searched: {tmp_path / 'user' / kind} \\(user\\)"):
            load("electroadhesion")


def test_sampling_linear_keeps_natural_coordinates(tmp_path):
    """`[sampling] linear` samples positive parameters in natural units (the empirical power law's
    b + d ridge is straight there); an unknown name is refused."""
    from skinfit.posterior import Posterior

    post = Posterior(skinfit.load_model("electroadhesion_empirical"), skinfit.load_priors("electroadhesion_empirical"),
                     skinfit.load_dataset("electroadhesion_synthetic"))
    assert {s.name: s.transform for s in post.slots} == {"b": "identity", "c_exp": "log", "d": "identity",
                                                         "sigma": "log"}
    text = (ROOT / "models" / "electroadhesion_empirical.toml").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('linear = ["b", "d"]', 'linear = ["b", "e"]'))
    with pytest.raises(skinfit.InputError, match=r"sampling.linear: names unknown parameter 'e'"):
        skinfit.load_model(str(bad))


def test_sampling_shift_and_product_declared_and_checked(tmp_path):
    """The electroadhesion card samples d_air as log(d_air + eps_air*t0) and beta0 as the product
    beta0*tau0*E*^(-2/3) in natural units; a split beta0 falls back to log; bad declarations are refused."""
    from skinfit.posterior import Posterior

    model, priors, data = (skinfit.load_model("electroadhesion"), skinfit.load_priors("electroadhesion"),
                           skinfit.load_dataset("electroadhesion_synthetic"))
    kinds = {s.name: s.transform for s in Posterior(model, priors, data).slots}
    assert kinds == {"E_star": "log", "tau0": "log", "d_air": "shift_log", "beta0": "product", "phi": "log",
                     "eta": "log", "alpha": "log", "sigma": "log"}
    split = Posterior(model, priors, data, split={"beta0": "voltage"})
    assert {s.transform for s in split.slots if s.base == "beta0"} == {"log"}
    text = (ROOT / "models" / "electroadhesion.toml").read_text()
    for old, new, message in [
        ("tau0 = 1.0, E_star", "beta0 = 1.0, E_star", r"partner 'beta0' must be another parameter"),
        ("tau0 = 1.0, E_star", "phi = 1.0, E_star", r"partner 'phi' must be another parameter"),
        ("tau0 = 1.0, E_star", "tau0 = 'x', E_star", r"exponent of 'tau0' must be a finite number"),
        ('d_air = "skinfit.physics.electroadhesion:air_gap_shift"',
         'phi = "skinfit.physics.electroadhesion:air_gap_shift"', r"'phi' has two sampling coordinates"),
        ('d_air = "skinfit.physics.electroadhesion:air_gap_shift"', 'd_air = "os:getcwd"',
             r"sampling.shift.d_air: 'os:getcwd' is not a registered shift function"),
    ]:
        bad = tmp_path / "bad.toml"
        assert old in text
        bad.write_text(text.replace(old, new, 1))
        with pytest.raises(skinfit.InputError, match=message):
            skinfit.load_model(str(bad))
