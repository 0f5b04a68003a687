"""Property tests over malformed user files: data CSV, dataset cards, model cards, prior files and
campaign files.  Whatever the damage, loading raises skinfit.errors.InputError (or succeeds on
a file that is still valid) -- never a bare numpy / pandas / tomllib / KeyError traceback -- and
no fit starts on bad input.  Each case starts from a shipped, valid file and damages it."""

import importlib
import json
import math
import shutil
import tempfile
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import skinfit
from skinfit.campaign import load_campaign
from skinfit.data import load_dataset
from skinfit.errors import InputError
from skinfit.models import load_model
from skinfit.posterior import Posterior
from skinfit.priors import load_priors

ROOT = Path(skinfit.__file__).resolve().parents[1]
DATA_DIR = ROOT / "datasets" / "electroadhesion_synthetic"
fit_module = importlib.import_module("skinfit.fit")  # (the package attribute `skinfit.fit` is the function)
SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# ---- a TOML writer (inline tables only: enough to write back any parsed document) -----------
def _value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v) if not isinstance(v, float) or math.isfinite(v) else ("nan" if math.isnan(v) else
                                                                                ("inf" if v > 0 else "-inf"))
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {_value(x)}" for k, x in v.items()) + "}"


def dumps(doc):
    return "".join(f"{json.dumps(k)} = {_value(v)}\n" for k, v in doc.items())


def test_writer_round_trips_every_shipped_card():
    for path in [*ROOT.glob("models/*.toml"), *ROOT.glob("priors/*.toml"), *ROOT.glob("datasets/*/dataset.toml"),
                 ROOT / "campaigns/example.toml"]:
        doc = tomllib.loads(path.read_text())
        assert tomllib.loads(dumps(doc)) == doc, path


# ---- damage to a parsed document -------------------------------------------------------------
scalars = st.one_of(st.text(max_size=12), st.integers(-10**20, 10**20), st.booleans(),
                    st.floats(allow_nan=True, allow_infinity=True), st.just(""), st.just(-1), st.just(0))
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=3),
                                                       st.dictionaries(st.text(max_size=6), inner, max_size=3)),
                      max_leaves=6)


def _paths(doc, prefix=()):
    """Every (container path, key) in a parsed document."""
    items = doc.items() if isinstance(doc, dict) else enumerate(doc)
    for k, v in items:
        yield prefix, k
        if isinstance(v, (dict, list)):
            yield from _paths(v, prefix + (k,))


@st.composite
def damaged(draw, doc, max_edits=3):
    doc = json.loads(json.dumps(doc))  # deep copy (shipped cards hold only JSON types)
    for _ in range(draw(st.integers(1, max_edits))):
        paths = list(_paths(doc))
        if not paths:
            break
        prefix, key = draw(st.sampled_from(paths))
        parent = doc
        for k in prefix:
            parent = parent[k]
        action = draw(st.sampled_from(["delete", "replace", "replace", "add"]))
        if action == "delete":
            del parent[key]
        elif action == "replace":
            parent[key] = draw(values)
        elif isinstance(parent, dict):
            parent[draw(st.text(min_size=1, max_size=8))] = draw(values)
        else:
            parent.append(draw(values))
    return doc


@st.composite
def damaged_text(draw, text):
    """Raw damage: TOML syntax errors, bad UTF-8, truncation."""
    raw = text.encode()
    i = draw(st.integers(0, len(raw)))
    kind = draw(st.sampled_from(["truncate", "insert", "delete"]))
    if kind == "truncate":
        return raw[:i]
    if kind == "insert":
        return raw[:i] + draw(st.binary(min_size=1, max_size=6)) + raw[i:]
    return raw[:i] + raw[i + draw(st.integers(1, 40)):]


def _load_ok_or_input_error(load):
    """Call ``load``; an InputError (or success) is fine, anything else fails the test."""
    try:
        return load()
    except InputError as exc:
        assert str(exc).strip(), "an InputError must say what is wrong"
        return None


# ---- data CSV ---------------------------------------------------------------------------------
CSV = (DATA_DIR / "data.csv").read_text().splitlines()[:13]
cells = st.one_of(st.text(max_size=8), st.sampled_from(["", "nan", "inf", "-1", "1e400", "0x10", "1,5", '"', "NA",
                                                        "\x00", "S01", "  3 ", "-0"]))


@st.composite
def damaged_csv(draw):
    rows = [line.split(",") for line in CSV]
    for _ in range(draw(st.integers(1, 4))):
        action = draw(st.sampled_from(["cell", "cell", "drop_column", "drop_cell", "extra_cell", "header",
                                       "raw_line", "no_rows"]))
        r = draw(st.integers(1, len(rows) - 1)) if len(rows) > 1 else 0
        c = draw(st.integers(0, len(rows[r]) - 1)) if rows[r] else 0
        if action == "cell" and rows[r]:
            rows[r][c] = draw(cells)
        elif action == "drop_column" and rows[0]:
            c = draw(st.integers(0, len(rows[0]) - 1))
            rows = [row[:c] + row[c + 1:] for row in rows]
        elif action == "drop_cell" and rows[r]:
            del rows[r][c]
        elif action == "extra_cell":
            rows[r].append(draw(cells))
        elif action == "header" and rows[0]:
            rows[0][draw(st.integers(0, len(rows[0]) - 1))] = draw(st.text(max_size=8))
        elif action == "raw_line":
            rows.insert(r, [draw(st.text(max_size=20))])
        elif action == "no_rows":
            rows = rows[:1]
    return "\n".join(",".join(row) for row in rows).encode() + draw(st.sampled_from([b"", b"\n", b"\xff\xfe"]))


def _dataset_dir(tmp, card_text=None, csv=None):
    d = Path(tmp) / "ds"
    d.mkdir()
    card = (DATA_DIR / "dataset.toml").read_text() if card_text is None else card_text
    (d / "dataset.toml").write_bytes(card.encode() if isinstance(card, str) else card)
    (d / "data.csv").write_bytes((DATA_DIR / "data.csv").read_bytes() if csv is None else csv)
    return d


@SETTINGS
@given(csv=damaged_csv())
def test_damaged_csv_gives_input_error(csv):
    with tempfile.TemporaryDirectory() as tmp:
        ds = _load_ok_or_input_error(lambda: load_dataset(_dataset_dir(tmp, csv=csv)))
        if ds is not None:  # still a valid file: every value finite, every required column there
            assert len(ds) > 0
            for c in ds.columns:
                if c.kind == "quantity" and not c.optional:
                    assert np.isfinite(ds.frame[c.name].to_numpy(dtype=float)).all()


@SETTINGS
@given(doc=damaged(tomllib.loads((DATA_DIR / "dataset.toml").read_text())))
def test_damaged_dataset_card_gives_input_error(doc):
    with tempfile.TemporaryDirectory() as tmp:
        _load_ok_or_input_error(lambda: load_dataset(_dataset_dir(tmp, card_text=dumps(doc))))


@SETTINGS
@given(raw=damaged_text((DATA_DIR / "dataset.toml").read_text()))
def test_damaged_dataset_card_text_gives_input_error(raw):
    with tempfile.TemporaryDirectory() as tmp:
        _load_ok_or_input_error(lambda: load_dataset(_dataset_dir(tmp, card_text=raw)))


# ---- model cards, prior files, campaign files ------------------------------------------------
def _write(tmp, name, content):
    path = Path(tmp) / name
    path.write_bytes(content.encode() if isinstance(content, str) else content)
    return path


MODEL_TEXT = (ROOT / "models" / "electroadhesion_coulomb.toml").read_text()
PRIOR_TEXT = (ROOT / "priors" / "electroadhesion_coulomb.toml").read_text()
CAMPAIGN_DOC = {"schema_version": 1, "seed": 3, "out": "runs", "models": ["electroadhesion_coulomb"],
                "datasets": ["electroadhesion_synthetic"], "by": ["voltage"], "fit": {"ess": 200, "max_steps": 400}}


@SETTINGS
@given(doc=damaged(tomllib.loads(MODEL_TEXT)))
def test_damaged_model_card_gives_input_error(doc):
    with tempfile.TemporaryDirectory() as tmp:
        _load_ok_or_input_error(lambda: load_model(_write(tmp, "m.toml", dumps(doc))))


@SETTINGS
@given(raw=damaged_text(MODEL_TEXT))
def test_damaged_model_card_text_gives_input_error(raw):
    with tempfile.TemporaryDirectory() as tmp:
        _load_ok_or_input_error(lambda: load_model(_write(tmp, "m.toml", raw)))


@SETTINGS
@given(ref=st.one_of(st.text(max_size=30), st.sampled_from(
    ["os:system", "skinfit.physics.electroadhesion:np", "skinfit.physics..x:f", "skinfit.physics.electroadhesion",
     "skinfit.physics.electroadhesion:__init__", "skinfit.physics.os:system", "skinfit.physics.\x00:f",
     "skinfit.physics.electroadhesion.np:sum", "builtins:eval"])))
def test_model_card_names_only_registered_physics_functions(ref):
    doc = tomllib.loads(MODEL_TEXT) | {"forward": ref}
    with tempfile.TemporaryDirectory() as tmp:
        model = _load_ok_or_input_error(lambda: load_model(_write(tmp, "m.toml", dumps(doc))))
    assert model is None or ref == "skinfit.physics.electroadhesion:electroadhesion_coulomb"


MODEL = load_model("electroadhesion_coulomb")
DATASET = load_dataset("electroadhesion_synthetic")


@SETTINGS
@given(doc=damaged(tomllib.loads(PRIOR_TEXT)))
def test_damaged_prior_file_gives_input_error_before_sampling(doc):
    with tempfile.TemporaryDirectory() as tmp:
        def load():
            post = Posterior(MODEL, load_priors(_write(tmp, "p.toml", dumps(doc))), DATASET)
            # a prior set that loads must give a finite, normalised log-prior at its own draws
            theta = post.sample_prior(64, np.random.default_rng(0))
            assert np.isfinite(post.log_prior(theta)).all()
        _load_ok_or_input_error(load)


@SETTINGS
@given(raw=damaged_text(PRIOR_TEXT))
def test_damaged_prior_file_text_gives_input_error(raw):
    with tempfile.TemporaryDirectory() as tmp:
        _load_ok_or_input_error(lambda: load_priors(_write(tmp, "p.toml", raw)))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(doc=damaged(CAMPAIGN_DOC))
def test_damaged_campaign_file_gives_input_error(doc):
    with tempfile.TemporaryDirectory() as tmp:
        _load_ok_or_input_error(lambda: load_campaign(_write(tmp, "c.toml", dumps(doc))))


# ---- priors refused before sampling (issue 6) -----------------------------------------------
@pytest.mark.parametrize("spec, match", [
    ('dist = "uniform"\nbounds = [0.0, inf]', "improper"),
    ('dist = "loguniform"\nbounds = [0.0, 2.0]', "needs lower > 0"),
    ('dist = "lognormal"\nmedian = 0.5\nsigma = 0.3\nbounds = [-1.0, 2.0]', "leave the support"),
    ('dist = "gamma"\nshape = 2.0\nscale = 0.1\nbounds = [-0.5, 2.0]', "leave the support"),
    ('dist = "normal"\nloc = 0.5\nscale = 0.3\nbounds = [2.0, 0.0]', "lower < upper"),
    ('dist = "normal"\nloc = 0.5\nscale = 0.0\nbounds = [0.0, 2.0]', "must be > 0"),
    ('dist = "normal"\nloc = 1e300\nscale = 1e-300\nbounds = [0.0, 2.0]', "no mass inside its bounds"),
])
def test_bad_prior_refused_before_sampling(tmp_path, monkeypatch, spec, match):
    text = PRIOR_TEXT.replace('dist = "normal"\nloc = 0.5\nscale = 0.3\nbounds = [0.0, 2.0]', spec)
    assert text != PRIOR_TEXT
    path = _write(tmp_path, "p.toml", text)
    monkeypatch.setattr(fit_module, "find_map", _no_fit)
    with pytest.raises(InputError, match=rf"p\.toml: mu\.(bounds|scale).*{match}"):
        skinfit.fit(MODEL, DATASET, priors=str(path))


def test_missing_prior_refused_before_sampling(tmp_path, monkeypatch):
    start = PRIOR_TEXT.index("[d_air]")
    text = PRIOR_TEXT[:start] + PRIOR_TEXT[PRIOR_TEXT.index("[sigma]"):]
    monkeypatch.setattr(fit_module, "find_map", _no_fit)
    with pytest.raises(InputError, match=r"p\.toml: no prior for d_air"):
        skinfit.fit(MODEL, DATASET, priors=str(_write(tmp_path, "p.toml", text)))


def _no_fit(*args, **kwargs):
    raise AssertionError("a fit started on bad input")


def test_no_fit_starts_on_a_bad_data_file(tmp_path, monkeypatch):
    monkeypatch.setattr(fit_module, "find_map", _no_fit)
    csv = (DATA_DIR / "data.csv").read_text().replace("S01,0,200.000,90.8425", "S01,0,200.000,n/a!", 1)
    d = _dataset_dir(tmp_path, csv=csv.encode())
    with pytest.raises(InputError, match=r"data\.csv: column 'tangential_force', row 1: expected a number"):
        skinfit.fit(MODEL, str(d))
    shutil.rmtree(d)


@pytest.mark.parametrize("old, new, name, physical", [
    ('dist = "lognormal"\nmedian = 40e3\nsigma = 0.6\nbounds = [2e3, 100e3]',
     'dist = "normal"\nloc = 40e3\nscale = 20e3\nbounds = [-1e3, 100e3]', "E_star", r"\[0, inf\]"),
    ('dist = "normal"\nloc = 0.5\nscale = 0.3\nbounds = [0.0, 2.0]',
     'dist = "normal"\nloc = 0.5\nscale = 0.3\nbounds = [-0.5, 2.0]', "mu", r"\[0, inf\]"),
    ('dist = "halfnormal"\nscale = 0.05\nbounds = [0.0, 1.0]',
     'dist = "normal"\nloc = 0.0\nscale = 0.05\nbounds = [-1.0, 1.0]', "sigma", r"\[0, inf\]"),
])
def test_prior_outside_physical_range_refused_before_sampling(tmp_path, monkeypatch, old, new, name, physical):
    """The card declares E_star, mu >= 0 (``physical = [0.0, inf]``); noise scales are >= 0."""
    assert old in PRIOR_TEXT
    path = _write(tmp_path, "p.toml", PRIOR_TEXT.replace(old, new))
    monkeypatch.setattr(fit_module, "find_map", _no_fit)
    with pytest.raises(InputError, match=rf"p\.toml: {name}\.bounds: .*leave the physical range {physical}"):
        skinfit.fit(MODEL, DATASET, priors=str(path))


@pytest.mark.parametrize("value", ["[1.0]", "[2.0, 1.0]", '["0", 1.0]', "[nan, 1.0]", "0.0"])
def test_malformed_physical_range_in_model_card(tmp_path, value):
    text = MODEL_TEXT.replace("physical = [0.0, inf]", f"physical = {value}", 1)
    assert text != MODEL_TEXT
    with pytest.raises(InputError, match=r"m\.toml: parameters\[\d\]\.physical: expected"):
        load_model(_write(tmp_path, "m.toml", text))


# ---- command-line numbers and model constants (issue 21, class 6) ------------------------------
#: integers far past int64 both ways, every float (NaN, infinities, subnormals) and short texts;
#: SETTINGS' 40 examples per test
cli_numbers = st.one_of(st.integers(-2**80, 2**80), st.floats(allow_nan=True, allow_infinity=True),
                        st.text(max_size=8), st.sampled_from(["0", "-0", "1e400", "0x10", "2**70", " 7 "]))


@SETTINGS
@given(option=st.sampled_from(["--seed", "--max-steps", "--ess", "--checkpoint-every"]), value=cli_numbers)
def test_class6_cli_numbers_parse_into_range_or_exit_2(option, value):
    from skinfit.cli import build_parser

    try:
        args = build_parser().parse_args(["fit", "m", "d", "--out", "o", option, str(value)])
    except SystemExit as exc:
        assert exc.code == 2
        return
    v = getattr(args, option[2:].replace("-", "_"))
    if option == "--seed":
        assert isinstance(v, int) and 0 <= v < 2**63
    elif option == "--max-steps":
        assert isinstance(v, int) and v >= 1
    else:
        assert 0 < v < math.inf


@SETTINGS
@given(value=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**6, 10**6)))
def test_class6_constant_override_valid_or_input_error(value):
    ds = load_dataset("electroadhesion_synthetic")
    model = load_model("electroadhesion_coulomb")
    try:
        post = Posterior(model, load_priors(model.id), ds, constants={"d_sc": value})
    except InputError as exc:
        assert not (math.isfinite(value) and value > 0) and "constants.d_sc: expected a finite number > 0" in str(exc)
        return
    assert math.isfinite(value) and value > 0 and post.constants["d_sc"] == value
