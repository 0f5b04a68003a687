"""Shipped textured and contact-area datasets: regeneration, data-boundary errors, recovery of
the generating parameters (truths inside 95% credible intervals), derived quantities."""

import importlib.util
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pointwise import check_pointwise_groups
from recovery import check_coverage as _check_coverage
from recovery import coverage as _coverage
from scipy import stats

import skinfit

ROOT = Path(skinfit.__file__).resolve().parents[1]
TEXTURED = ROOT / "datasets" / "textured_synthetic"
CONTACT = ROOT / "datasets" / "contact_area_synthetic"
TX_CARD = tomllib.loads((TEXTURED / "dataset.toml").read_text())["provenance"]
CA_CARD = tomllib.loads((CONTACT / "dataset.toml").read_text())["provenance"]


@pytest.mark.parametrize("folder", [TEXTURED, CONTACT])
def test_make_regenerates_data_byte_for_byte(folder, tmp_path):
    spec = importlib.util.spec_from_file_location(f"make_{folder.name}", folder / "make.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(tmp_path / "data.csv")
    assert (tmp_path / "data.csv").read_bytes() == (folder / "data.csv").read_bytes()


# ---- missing by design vs missing data ------------------------------------------------------
@pytest.fixture
def tx_dir(tmp_path):
    d = tmp_path / "tx"
    shutil.copytree(TEXTURED, d)
    return d


def _edit(d, row, column, value):
    lines = (d / "data.csv").read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[row].split(",")
    cells[header.index(column)] = value
    lines[row] = ",".join(cells)
    (d / "data.csv").write_text("\n".join(lines) + "\n")


def _row_of(d, texture):
    lines = (d / "data.csv").read_text().splitlines()
    return next(i for i, line in enumerate(lines[1:], 1) if line.split(",")[1] == texture)


def test_flat_reference_texture_is_missing_by_design():
    ds = skinfit.load_dataset("textured_synthetic")
    flat = ds.frame["texture"] == "flat"
    for c in ("asperity_radius", "asperity_height", "asperity_spacing"):
        assert ds.frame.loc[flat, c].isna().all() and ds.frame.loc[~flat, c].notna().all()
    spacing = ds.frame.loc[~flat, "asperity_spacing"].to_numpy()
    assert np.all(np.isclose(spacing, 100e-6, rtol=1e-12) | np.isclose(spacing, 200e-6, rtol=1e-12))
    assert ds.units["asperity_radius"] == "um" and ds.units["sample_modulus"] == "MPa"


@pytest.mark.parametrize("texture,column,value,match", [
    ("L200", "asperity_height", "", r"data.csv: column 'asperity_height', row {row}: missing value \(expected a "
     r"number in um; only rows with texture = 'flat' leave it empty by design\)"),
    ("L100", "asperity_spacing", "NaN", r"column 'asperity_spacing', row {row}: missing value"),
    ("flat", "asperity_radius", "19.0", r"column 'asperity_radius', row {row}: expected no value on a row with "
     r"texture = 'flat' \(missing by design; got '19.0'\)"),
    ("L200", "normal_force", "", r"column 'normal_force', row {row}: missing value"),
    ("L100", "sample_modulus", "abc", r"column 'sample_modulus', row {row}: expected a number in MPa"),
])
def test_missing_data_is_an_error_naming_file_column_row(tx_dir, texture, column, value, match):
    row = _row_of(tx_dir, texture) + 3
    _edit(tx_dir, row, column, value)
    with pytest.raises(skinfit.InputError, match=match.format(row=row)):
        skinfit.load_dataset(str(tx_dir))


def test_missing_when_must_name_a_declared_column(tx_dir):
    card = (tx_dir / "dataset.toml").read_text().replace('column = "texture"', 'column = "surface"', 1)
    (tx_dir / "dataset.toml").write_text(card)
    with pytest.raises(skinfit.InputError, match=r"columns.asperity_radius.missing_when.column: names column "
                                                  r"'surface', which is not declared"):
        skinfit.load_dataset(str(tx_dir))


# ---- recovery -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tx_fit():
    return skinfit.fit("textured_surface", "textured_synthetic", split={"beta_h": "material"}, rng=1)


def test_textured_recovery_truth_in_95_interval(tx_fit):
    assert tx_fit.converged
    post = tx_fit.idata["posterior"].to_dataset()
    truth = {**TX_CARD["generating_parameters"], "sigma": TX_CARD["noise"]["sigma"]}
    checks = [(name, post[name].values, value) for name, value in truth.items()]
    checks += [(f"beta_h[{level}]", post["beta_h"].sel(material=level).values, value)
               for level, value in TX_CARD["generating_split"]["beta_h"].items()]
    _check_coverage(checks)
    table = tx_fit.summary()
    assert {"beta_h[M10]", "beta_h[M60]"} <= set(table.index)
    # the forces pin the transition (E_skin_micro) and the area law; E_fingerpad enters only
    # through the small hysteresis term: mostly prior
    assert table.loc["E_skin_micro", "contraction"] > 0.95 and table.loc["m_a", "contraction"] > 0.95
    assert table.loc["E_fingerpad", "note"].startswith("mostly prior")


def _contact_fit(subject, **kw):
    ds = skinfit.load_dataset("contact_area_synthetic")
    return skinfit.fit("contact_area", ds.subset(ds.frame["subject"] == subject, subject), rng=1, **kw)


def _contact_checks(fit, subject):
    """(name, draws, truth) for the parameters and for the derived gamma, p at each f_a."""
    assert fit.converged
    truth = {**CA_CARD["subjects"][subject], "sigma_contact_area": CA_CARD["noise"]["sigma_contact_area"],
             "sigma_impedance": CA_CARD["noise"]["sigma_impedance"]}
    post = fit.idata["posterior"].to_dataset()
    params = [(f"{subject} {name}", post[name].values, value) for name, value in truth.items()]
    # derived gamma, p of A = gamma*|Z|**p at each actuation force, against the truth's closed form
    der = fit.idata["derived"].to_dataset()
    derived = []
    for level in der["p"].coords["actuation_force"].values:
        fa = float(level)
        m, n = truth["m0"] + truth["m1"] * fa, truth["n_z0"] + truth["n_z1"] * fa
        gamma = truth["alpha_a0"] * np.exp(truth["alpha_a1"] * fa) / (truth["beta_z0"] * np.exp(truth["beta_z1"] * fa)) ** (m / n)
        derived += [(f"{subject} p[{level}]", der["p"].sel(actuation_force=level).values, m / n),
                    (f"{subject} gamma[{level}]", der["gamma"].sel(actuation_force=level).values, gamma)]
    return params, derived


def _check_contact_recovery(fit, subject):
    params, derived = _contact_checks(fit, subject)
    _check_coverage(params + derived)


@pytest.fixture(scope="module")
def ca_fit():
    return _contact_fit("S01")


def test_contact_area_recovery_s01(ca_fit):
    _check_contact_recovery(ca_fit, "S01")


@pytest.mark.parametrize("subject", ["S07", "S12"])
def test_contact_area_recovery_more_subjects(subject):
    _check_contact_recovery(_contact_fit(subject, ess_target=200), subject)


@pytest.mark.slow
def test_contact_area_recovery_every_subject():
    """All 13 subjects (~2 min): pooled over the 130 parameter truths, the number outside their
    95% intervals is what Binomial(130, 0.05) allows at 99%; every truth, parameter or derived,
    inside its 99.9% interval (390 checks: a 99% interval would be missed ~4 times by chance)."""
    params, derived = [], []
    for subject in sorted(CA_CARD["subjects"]):
        p, d = _contact_checks(_contact_fit(subject), subject)
        params += p
        derived += d
    outside = _coverage(params + derived, 0.999)
    n_out = sum(1 for o in outside if "[" not in o.split(":")[0])
    assert n_out <= stats.binom.ppf(0.99, len(params), 0.05), outside


def test_derived_group_values_summary_and_save(ca_fit, tmp_path):
    """The card's [derived] quantities: evaluated on every draw, listed by summary(), saved."""
    tree = ca_fit.idata
    post, der = tree["posterior"].to_dataset(), tree["derived"].to_dataset()
    assert der["gamma"].dims == ("chain", "draw", "actuation_force")
    assert list(der["p"].coords["actuation_force"].values) == ["0", "5", "10", "15", "20", "25", "30"]
    fa = 20.0
    m, n = post["m0"] + post["m1"] * fa, post["n_z0"] + post["n_z1"] * fa
    np.testing.assert_allclose(der["p"].sel(actuation_force="20").values, (m / n).values, rtol=1e-13)
    gamma = post["alpha_a0"] * np.exp(post["alpha_a1"] * fa) / (post["beta_z0"] * np.exp(post["beta_z1"] * fa)) ** (m / n)
    np.testing.assert_allclose(der["gamma"].sel(actuation_force="20").values, gamma.values, rtol=1e-12)
    table = ca_fit.summary()
    assert table.loc["p[20]", "mean"] == pytest.approx(float((m / n).mean()), rel=1e-12)
    assert table.loc["gamma[0]", "note"] == "derived [m^2/(N*s/m)^p]" and np.isnan(table.loc["p[0]", "map"])
    back = skinfit.load_fit(ca_fit.save(tmp_path / "fit.nc"))
    np.testing.assert_array_equal(back.idata["derived"]["gamma"].values, der["gamma"].values)
    pd.testing.assert_frame_equal(back.summary(), table)


def test_pointwise_groups_of_two_lognormal_observables(ca_fit):
    check_pointwise_groups(ca_fit)


def test_derived_function_must_return_the_declared_quantities(tmp_path):
    text = (ROOT / "models" / "contact_area.toml").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('quantities = { gamma = "m^2/(N*s/m)^p", p = "1" }', 'quantities = { gamma = "m^2" }'))
    model = skinfit.load_model(str(bad))
    with pytest.raises(skinfit.InputError, match=r"derived.quantities: .* returns \['gamma', 'p'\], the card "
                                                  r"declares \['gamma'\]"):
        model.derive({k: np.array([[v]]) for k, v in CA_CARD["subjects"]["S01"].items()},
                     {"normal_force": np.ones(2), "actuation_force": np.zeros(2)})
    bad.write_text(text.replace("contact_area:derived\"", "contact_area:nothere\""))
    with pytest.raises(skinfit.InputError, match=r"derived.function: 'skinfit.physics.contact_area:nothere' is not "
                                                  r"a registered derived function"):
        skinfit.load_model(str(bad))
