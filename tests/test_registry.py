"""Class 7 of issue 21 (cards that name the wrong code): a card can name only a function
registered for the role it names it in (forward model, [sampling] shear / shift, [derived]),
checked with its signature when the card is loaded; a prior file for another model and unknown
units on a model card are refused.  Every refusal is one line naming the file and the key."""

import inspect
from pathlib import Path

import pytest

import skinfit
from skinfit.errors import InputError
from skinfit.io import registry

ROOT = Path(skinfit.__file__).resolve().parents[1]
EA = (ROOT / "models" / "electroadhesion.toml").read_text()
CA = (ROOT / "models" / "contact_area.toml").read_text()


def _card(tmp_path, text):
    path = tmp_path / "card.toml"
    path.write_text(text)
    return str(path)


def test_every_registered_function_has_its_roles_signature():
    for role, refs in registry.BUILTIN.items():
        for ref in refs:
            f = registry.resolve(role, ref, "test")
            assert list(inspect.signature(f).parameters)[:len(registry.ROLES[role])] == list(registry.ROLES[role])


@pytest.mark.parametrize("ref, match", [
    ("skinfit.physics._cache:by_value", "is not a registered forward function"),          # a cache helper
    ("skinfit.physics.ultrasonic:PHASES", "is not a registered forward function"),        # an int constant
    ("skinfit.physics.electroadhesion:phi_offset", "is registered as a shear function, not a forward"),
    ("skinfit.physics.contact_area:derived", "is registered as a derived function, not a forward"),
    ("skinfit.physics.electroadhesion:jkr_area", "is not a registered forward function"),  # a helper
    ("os:system", "is not a registered forward function"),
])
def test_class7_forward_naming_unregistered_code_refused_at_load(tmp_path, ref, match):
    bad = EA.replace('"skinfit.physics.electroadhesion:electroadhesion"', f'"{ref}"')
    with pytest.raises(InputError, match=rf"card.toml: forward: '{ref}' {match}") as err:
        skinfit.load_model(_card(tmp_path, bad))
    assert "\n" not in str(err.value)


def test_class7_sampling_and_derived_roles_checked_at_load(tmp_path):
    cases = [
        (EA.replace('phi = "skinfit.physics.electroadhesion:phi_offset"',
                    'phi = "skinfit.physics.electroadhesion:air_gap_shift"'),
         r"sampling.shear.phi: 'skinfit.physics.electroadhesion:air_gap_shift' is registered as a shift function"),
        (EA.replace('d_air = "skinfit.physics.electroadhesion:air_gap_shift"',
                    'd_air = "skinfit.physics.electroadhesion:electroadhesion"'),
         r"sampling.shift.d_air: 'skinfit.physics.electroadhesion:electroadhesion' is registered as a forward"),
        (CA.replace('function = "skinfit.physics.contact_area:derived"',
                    'function = "skinfit.physics.contact_area:area_impedance_law"'),
         r"derived.function: 'skinfit.physics.contact_area:area_impedance_law' is not a registered derived"),
    ]
    for text, match in cases:
        with pytest.raises(InputError, match=match):
            skinfit.load_model(_card(tmp_path, text))


def test_class7_short_registered_names_accepted_and_equal_to_the_full_reference(tmp_path):
    model = skinfit.load_model(_card(tmp_path, EA.replace('"skinfit.physics.electroadhesion:electroadhesion"',
                                                          '"electroadhesion"')))
    assert model.forward is skinfit.load_model("electroadhesion").forward


def test_class7_a_registered_function_with_the_wrong_signature_is_refused():
    def two_args(p, x):
        return p

    with pytest.raises(InputError, match=r"plug: forward: two_args\(p, x\) cannot be a forward function: "
                                         r"it must take \(p, x, c\)"):
        registry._check_signature("forward", two_args, "plug", "forward")
    with pytest.raises(InputError, match=r"names int 3, not a function"):
        registry._check_signature("shift", 3, "plug", "sampling.shift.x")


def test_class7_prior_file_for_another_model_refused(tmp_path):
    text = (ROOT / "priors" / "electroadhesion_coulomb.toml").read_text()
    path = tmp_path / "p.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=r"p.toml: model: is a prior file for model 'electroadhesion_coulomb', "
                                         r"not for 'electroadhesion'"):
        skinfit.fit("electroadhesion", "electroadhesion_synthetic", priors=str(path), rng=1)


@pytest.mark.parametrize("old, new, field", [
    ('name = "tangential_force"\nunit = "N"', 'name = "tangential_force"\nunit = "newtons please"',
     r"observables\[0\].unit"),
    ('name = "normal_force"\nunit = "N"', 'name = "normal_force"\nunit = "mN"', r"covariates\[0\].unit"),
    ('name = "d_air"\nunit = "m"', 'name = "d_air"\nunit = "um"', r"parameters\[2\].unit"),
    ('unit = "F/m"', 'unit = "F/furlong"', r"constants.eps0.unit"),
])
def test_class7_unknown_or_non_si_units_on_a_model_card_refused(tmp_path, old, new, field):
    assert old in EA
    with pytest.raises(InputError, match=rf"card.toml: {field}: unknown unit .*not a coherent SI unit"):
        skinfit.load_model(_card(tmp_path, EA.replace(old, new, 1)))


def test_class4_ids_are_names_not_paths(tmp_path):
    for bad in ("../../x", "/etc/x", "a/b", "..", ".hidden", "a b"):
        with pytest.raises(InputError, match=r"card.toml: id: expected a name"):
            skinfit.load_model(_card(tmp_path, EA.replace('id = "electroadhesion"', f'id = "{bad}"')))
    for kind, load in (("models", skinfit.load_model), ("priors", skinfit.load_priors),
                       ("datasets", skinfit.load_dataset)):
        with pytest.raises(InputError, match="an id is a name, not a path"):
            load("../" + kind + "/electroadhesion")
    prior = (ROOT / "priors" / "electroadhesion.toml").read_text().replace('model = "electroadhesion"',
                                                                              'model = "../x"')
    (tmp_path / "p.toml").write_text(prior)
    with pytest.raises(InputError, match=r"p.toml: model: expected a name"):
        skinfit.load_priors(str(tmp_path / "p.toml"))
