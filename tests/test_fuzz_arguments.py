"""Property tests over hostile arguments to skinfit's Python entry points (issue 39, point 14).

Four classes, each generated: (1) what is not a path, or a path to something that is not a
regular file (a directory, a FIFO, a device, a sparse 4 GiB file) where a card, a data file, a
fit or an index is expected; (2) what is not a Fit where a Fit is expected; (3) numbers out of
range or of the wrong type (negative, zero, NaN, inf, a bool, a float for a count, a string) and
counts whose arrays would exhaust memory (refused with a size estimate); (4) places a fit or a
checkpoint cannot be written to.  Every call either starts its work (a stand-in raises
``_WorkStarted`` there) on a value that is valid by the rule stated here, or raises a one-line
InputError (an InputTypeError, also a TypeError, for a wrong type) before any work -- never a
traceback from numpy, pathlib, h5py or xarray, never a hang on a FIFO or /dev/zero.
"""

import importlib
import math
import os
import stat
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import skinfit
from skinfit.errors import InputError, InputTypeError

MODEL, DATASET = "electroadhesion_coulomb", "electroadhesion_synthetic"
run_module = importlib.import_module("skinfit.inference.run")
SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                          HealthCheck.function_scoped_fixture])
#: memory the size checks see (patched): 8 GiB, so that what is refused does not depend on the machine
MEMORY = 8 * 2**30


class _WorkStarted(Exception):
    """Raised by the stand-ins for the first expensive step of each entry point."""


def _work(*args, **kwargs):
    raise _WorkStarted


@pytest.fixture(scope="module")
def small_fit():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return skinfit.fit(MODEL, DATASET, rng=3, ess_target=50, max_steps=400)


@pytest.fixture(scope="module")
def places(tmp_path_factory):
    """Paths that are not what a reader expects: a folder, a FIFO, an empty file, a sparse 4 GiB
    file and binary junk under the names of a card, a data file, a fit and an index."""
    root = tmp_path_factory.mktemp("places")
    folder = root / "folder.toml"
    folder.mkdir()
    fifo = root / "fifo.nc"
    os.mkfifo(fifo)
    (root / "empty.csv").write_bytes(b"")
    names = {"folder": folder, "fifo": fifo, "empty": root / "empty.csv", "missing": root / "no" / "such.toml",
             "unicode": root / "\u00b5\u202e.toml"}
    for suffix in (".toml", ".csv", ".nc", ".json"):
        huge = root / f"huge{suffix}"
        with open(huge, "wb") as fh:
            fh.truncate(4 * 2**30)  # sparse: no disk used
        names[f"huge{suffix}"] = huge
        (root / f"junk{suffix}").write_bytes(bytes(range(256)) * 8)
        names[f"junk{suffix}"] = root / f"junk{suffix}"
    names["fifo_dir"] = root / "run"
    names["fifo_dir"].mkdir()
    os.mkfifo(names["fifo_dir"] / "index.json")
    os.mkfifo(root / "fit_fifo_run")  # a run "directory" that is a FIFO
    names["fifo_run"] = root / "fit_fifo_run"
    names["dev_zero"] = "/dev/zero"
    names["dev_null"] = "/dev/null"
    return names


#: values of the wrong type for a path, a Fit, a model or a number
OBJECTS = [None, {}, {"a": 1}, np.zeros(3), np.zeros((2, 2)), 5, -1, 0, 1.5, math.nan, math.inf, True, b"bytes",
           [1, 2], (), object(), "", "   "]


@pytest.fixture(autouse=True)
def _no_work(monkeypatch):
    """The first expensive step of each entry point raises _WorkStarted; memory is MEMORY."""
    monkeypatch.setattr(run_module, "find_map", _work)
    monkeypatch.setattr(run_module, "available_memory", lambda: MEMORY)
    monkeypatch.setattr(importlib.import_module("skinfit.io.arguments"), "available_memory", lambda: MEMORY)
    sbc = importlib.import_module("skinfit.analysis.sbc")
    monkeypatch.setattr(sbc, "_map", _work)
    evidence = importlib.import_module("skinfit.analysis.evidence.estimate")
    for name in ("bridge_sampling", "laplace", "nested"):
        monkeypatch.setattr(evidence, name, _work)
    monkeypatch.setattr(importlib.import_module("skinfit.analysis.compare"), "evidence", _work)


def _refused(call):
    """The InputError ``call()`` raises: one line, and no work started."""
    with pytest.raises(InputError) as info:
        call()
    assert "\n" not in str(info.value)
    return info.value


# ---- class 1: what is not a path, or a path to what is not a regular file ----------------------
LOADERS = {
    "load_model": lambda v: skinfit.load_model(v),
    "load_priors": lambda v: skinfit.load_priors(v),
    "load_dataset": lambda v: skinfit.load_dataset(v),
    "load_fit": lambda v: skinfit.load_fit(v),
    "load_groups": lambda v: importlib.import_module("skinfit.analysis.groups").load_groups(v),
    "fit(model=)": lambda v: skinfit.fit(v, DATASET),
    "fit(dataset=)": lambda v: skinfit.fit(MODEL, v),
    "fit(priors=)": lambda v: skinfit.fit(MODEL, DATASET, priors=v),
    "run_sbc(model=)": lambda v: importlib.import_module("skinfit.analysis.sbc").run_sbc(v, n_sims=1),
    "design(fit_or_model=)": lambda v: skinfit.design(v, {"normal_force": np.array([0.5, 1.0])}, n=1),
}


@SETTINGS
@given(target=st.sampled_from(sorted(LOADERS)),
       value=st.one_of(st.sampled_from(OBJECTS), st.sampled_from(["folder", "fifo", "empty", "missing", "unicode",
                                                                  "huge.toml", "huge.csv", "huge.nc", "huge.json",
                                                                  "junk.toml", "junk.csv", "junk.nc", "junk.json",
                                                                  "fifo_dir", "fifo_run", "dev_zero", "dev_null"])))
def test_class_special_paths_and_wrong_types_refused_in_one_line_by_every_loader(places, target, value):
    """Class 1 (17 places x 18 objects x 10 entry points): never read without end, never waited
    on, never a pathlib / h5py TypeError; ``priors=None`` alone is valid (the model's own file)."""
    value = places.get(value, value) if isinstance(value, str) else value
    if target == "fit(priors=)" and value is None:
        with pytest.raises(_WorkStarted):
            LOADERS[target](value)
        return
    error = _refused(lambda: LOADERS[target](value))
    if not isinstance(value, (str, os.PathLike)):  # a wrong type: also the TypeError Python's convention expects
        assert isinstance(error, InputTypeError) and isinstance(error, TypeError), (target, value, error)


# ---- class 2: what is not a Fit where a Fit is expected ----------------------------------------
FIT_USERS = {
    "evidence": lambda v: skinfit.evidence(v),
    "compare([v, v])": lambda v: skinfit.compare([v, v]),
    "compare({a: v, b: v})": lambda v: skinfit.compare({"a": v, "b": v}),
    "level_contrasts": lambda v: importlib.import_module("skinfit.analysis.contrasts").level_contrasts(v, "mu"),
    "fit_contrasts": lambda v: importlib.import_module("skinfit.analysis.contrasts").fit_contrasts({"a": v, "b": v}, "mu"),
}


@SETTINGS
@given(target=st.sampled_from(sorted(FIT_USERS)), value=st.sampled_from(OBJECTS + [
    "fifo", "dev_zero", "missing", "folder", "junk.nc", "huge.nc"]))
def test_class_not_a_fit_where_a_fit_is_expected_refused_in_one_line(places, target, value):
    value = places.get(value, value) if isinstance(value, str) else value
    error = _refused(lambda: FIT_USERS[target](value))
    if not isinstance(value, (str, os.PathLike)):
        assert isinstance(error, InputTypeError) and isinstance(error, TypeError), (target, value, error)


@pytest.mark.parametrize("value", [None, 5, np.zeros(3), [1, 2], [None, None]], ids=repr)
def test_class_not_a_fit_population_refused_in_one_line(value):
    population = importlib.import_module("skinfit.analysis.population.population").population
    _refused(lambda: population(value))


def test_class_not_a_fit_compare_of_a_mapping_compares_its_fits(small_fit):
    """A mapping label -> Fit (the documented form) is compared by its values, not its keys."""
    with pytest.raises(_WorkStarted):
        skinfit.compare({"one": small_fit, "two": small_fit})
    with pytest.raises(InputTypeError, match=r"compare: fits: expected a list of fits .* \(got 'abc'\)"):
        skinfit.compare("abc")


# ---- class 3: numbers out of range, of the wrong type, or too large for memory ------------------
#: (lo, hi, refused_when_huge): an integer count is valid when lo <= v <= hi and, if the third is
#: true, when v is no more than a million (from 1e9 on its arrays exceed MEMORY); a float is valid
#: in (lo, hi) when finite.  Stated here from the sizes involved, not read from skinfit.
COUNTS = {
    ("fit", "max_steps"): (1, None, True), ("fit", "nwalkers"): (8, None, True),  # 4 parameters: 2 walkers each
    ("fit", "n_global"): (1, None, True), ("fit", "n_local"): (0, 2000, False),
    ("fit", "n_prior_draws"): (1, None, True),
    ("evidence", "n_repeats"): (1, 10_000, False),
    ("run_sbc", "n_sims"): (1, None, True), ("run_sbc", "n_draws"): (1, None, True),
    ("run_sbc", "seed"): (0, None, False), ("run_sbc", "n_rows"): (1, None, False),
    ("run_sbc", "max_steps"): (1, None, True), ("run_sbc", "n_global"): (1, None, True),
    ("run_sbc", "jobs"): (1, None, False),
}
REALS = {("fit", "ess_target"): (0, math.inf), ("fit", "checkpoint_every"): (0, math.inf),
         ("run_sbc", "ess_target"): (0, math.inf), ("run_sbc", "alpha"): (0, 1)}
NUMBERS = [-10**30, -10**12, -1, 0, 1, 2, 3, 7, 8, 100, 10**9, 10**12, 10**30, np.int64(5), -0.0, 0.5, 1.0, 2.5,
           math.nan, math.inf, -math.inf, np.float32(0.25), True, False, np.True_, "3", None, 1e300, 5e-324]


def _call(fn, name, value, fit):
    kwargs = {name: value}
    if fn == "fit":
        return skinfit.fit(MODEL, DATASET, **kwargs)
    if fn == "evidence":
        return skinfit.evidence(fit, refresh=True, **kwargs)
    return importlib.import_module("skinfit.analysis.sbc").run_sbc(MODEL, **{"n_sims": 2, **kwargs})


def _valid(key, value):
    if value is None and key in (("run_sbc", "n_rows"), ("fit", "nwalkers")):  # optional: every row; the default
        return True
    if key in COUNTS:
        lo, hi, huge = COUNTS[key]
        if not isinstance(value, (int, np.integer)) or isinstance(value, (bool, np.bool_)):
            return False
        return lo <= value and (hi is None or value <= hi) and not (huge and value > 10**6)
    lo, hi = REALS[key]
    if isinstance(value, (bool, np.bool_, str)) or value is None:
        return False
    return math.isfinite(value) and lo < value < hi


@SETTINGS
@given(key=st.sampled_from(sorted(COUNTS) + sorted(REALS)), value=st.sampled_from(NUMBERS))
def test_class_numbers_accepted_exactly_when_valid_else_one_line_before_work(small_fit, key, value):
    """Class 3: 17 arguments x 29 values (~500 cases, 40 drawn a run)."""
    fn, name = key
    if _valid(key, value):
        with pytest.raises(_WorkStarted):
            _call(fn, name, value, small_fit)
        return
    error = _refused(lambda: _call(fn, name, value, small_fit))
    assert f"{name}: " in str(error)
    if isinstance(value, int) and not isinstance(value, bool) and value >= 10**9 and key in COUNTS and COUNTS[key][2]:
        assert "would need" in str(error) and "memory available" in str(error)  # a size estimate and a refusal


@pytest.mark.parametrize("kwargs, match", [
    ({"max_steps": 10**12}, r"max_steps: a chain of 1,000,000,000,000 steps x 32 walkers x 4 parameters would need "
                            r"\d.* PiB, more than the 8\.0 GiB of memory available: give max_steps \(--max-steps\) at "
                            r"most 3,355,443"),
    ({"nwalkers": 10**9}, r"nwalkers: one step of 1,000,000,000 walkers x 4 parameters would need 89\.4 GiB"),
    ({"n_global": 10**9}, r"n_global: scoring 1,000,000,000 prior draws would need 223\.5 GiB"),
])
def test_class_huge_counts_refused_with_a_size_estimate(kwargs, match):
    """Sizes from the shapes: the chain holds, per step, 32 walkers x (4 parameters + 2) float64
    and is copied while emcee grows it (2 x 32 x 6 x 8 = 3072 bytes), so MEMORY holds
    MEMORY // 3072 steps; one step of 1e9 walkers is 2 x 1e9 x 6 x 8 bytes = 89.4 GiB; scoring
    1e9 prior draws keeps ~6 float64 arrays of (draws, 4 + 1) = 223.5 GiB."""
    match = match.replace("3,355,443", f"{MEMORY // (2 * 32 * 6 * 8):,}")
    _refused(lambda: skinfit.fit(MODEL, DATASET, **kwargs))
    with pytest.raises(InputError, match=match):
        skinfit.fit(MODEL, DATASET, **kwargs)


@pytest.mark.parametrize("kwargs, match", [
    ({"rng": 1.5}, r"rng must be an int seed >= 0"), ({"rng": "7"}, r"rng must be an int seed >= 0"),
    ({"rng": True}, r"rng must be an int seed >= 0"), ({"rng": -3}, r"rng: expected a seed 0 \.\. 2\*\*63-1"),
    ({"progress": "no"}, r"progress: expected True or False \(got 'no'\)"),
    ({"strict": None}, r"strict: expected True or False"),
    ({"split": "voltage"}, r"split: expected a mapping parameter -> column"),
    ({"split": {"mu": 3}}, r"split: expected mu = a column name or a list of column names \(got 3\)"),
    ({"noise": {"friction": "normal"}}, r"noise: no observable \['friction'\] in the data"),
    ({"noise": 3}, r"noise: expected a noise model name or a mapping"),
    ({"constants": [1, 2]}, r"constants: expected a mapping constant name -> number"),
    ({"units": "mN"}, r"units: expected a mapping column -> unit"),
    ({"priors": ""}, r"expected a PriorSet, a mapping parameter -> scipy.stats distribution, a prior file id or the path "
                     r"of a prior file \(got ''\)"),
    ({"nwalkers": 7}, r"nwalkers: expected at least 2 walkers per sampled parameter, 8 for the 4 of this fit"),
])
def test_class_wrong_settings_of_fit_refused_before_the_map(kwargs, match):
    _refused(lambda: skinfit.fit(MODEL, DATASET, **kwargs))
    with pytest.raises(InputError, match=match):
        skinfit.fit(MODEL, DATASET, **kwargs)


def test_class_wrong_settings_of_evidence_and_contrasts_refused(small_fit):
    contrasts = importlib.import_module("skinfit.analysis.contrasts")
    for call, match in [
        (lambda: skinfit.evidence(small_fit, method="bridges"), r"evidence: method: unknown evidence method 'bridges'"),
        (lambda: skinfit.evidence(small_fit, refresh=True, tol_x=1), r"unknown option\(s\) tol_x of method 'bridge' "
                                                                      r"\(options: tol, max_iter\)"),
        (lambda: skinfit.evidence(small_fit, rng=-1), r"evidence: rng: expected a seed, a whole number >= 0"),
        (lambda: skinfit.compare([small_fit, small_fit], method="loo"), r"compare: method: unknown evidence method"),
        (lambda: contrasts.fit_contrasts({"a": small_fit, "b": small_fit}, "mu", prob=1.5),
         r"fit_contrasts: prob: expected an interval probability between 0 and 1 \(got 1\.5\)"),
        (lambda: contrasts.fit_contrasts({"a": small_fit, "b": small_fit}, ["mu"]),
         r"fit_contrasts: parameter: expected the name of a sampled parameter \(got list \['mu'\]\)"),
    ]:
        with pytest.raises(InputError, match=match):
            call()


# ---- class 4: places a fit or a checkpoint cannot be written to --------------------------------
def _device(tmp_path):
    """A character device like /dev/null (mknod, as root), else None: never the real /dev/null,
    which an atomic rename onto it would replace for the whole machine."""
    path = tmp_path / "null"
    try:
        os.mknod(path, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    except (PermissionError, OSError):
        return None
    return path


def test_class_unwritable_places_fit_save_refuses_before_writing(small_fit, tmp_path):
    fifo = tmp_path / "fifo.nc"
    os.mkfifo(fifo)
    (tmp_path / "file").write_text("x")
    device = _device(tmp_path)
    cases = [(tmp_path, r"is a directory: give the path of the fit file to write, e\.g\. .*/fit\.nc"),
             (fifo, r"is a FIFO: give the path of the fit file to write"),
             (tmp_path / "file" / "fit.nc", r"cannot write the fit here: .*/file is a file, not a folder"),
             ("", r"Fit\.save: path: expected the path of the fit file \(got ''\)"),
             (3, r"Fit\.save: path: expected the path of the fit file \(got 3\)")]
    if device is not None:
        cases.append((device, r"is a device: give the path of the fit file to write"))
    for path, match in cases:
        with pytest.raises(InputError, match=match):
            small_fit.save(path)
    assert stat.S_ISFIFO(os.stat(fifo).st_mode) and (tmp_path / "file").read_text() == "x"
    if device is not None:
        assert stat.S_ISCHR(os.stat(device).st_mode)


def test_class_unwritable_places_checkpoint_refused_before_the_map(tmp_path):
    fifo = tmp_path / "ckpt.h5"
    os.mkfifo(fifo)
    for path, match in [(tmp_path, r"is a directory: give the path of the checkpoint file to write"),
                        (fifo, r"is a FIFO: give the path of the checkpoint file to write"),
                        (b"bytes.h5", r"fit: checkpoint: expected the path of the checkpoint file")]:
        with pytest.raises(InputError, match=match):
            skinfit.fit(MODEL, DATASET, rng=1, checkpoint=path)
