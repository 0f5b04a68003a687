"""skinfit.ingest: raw recordings simulated from the physics (tests/recordings.py) through the
issue's rig file, written as MATLAB v5, v7.3 and HDF5; strokes counted, stroke means checked
against the generating values within their reported standard errors, off-target trials rejected."""

import hashlib

import h5py
import numpy as np
import pytest
import scipy.io
from recordings import ISSUE_RIG, rig_volts, stroke_recording, write_mat_v73

import skinfit
from skinfit.apps.cli import main
from skinfit.errors import InputError
from skinfit.io.recordings.ingest import run_ingest
from skinfit.io.recordings.rig import load_rig

#: The issue's rig with a 50 Hz notch and a bias drift corrected between the first and last 0.5 s.
RIG = ISSUE_RIG.replace(
    'lowpass = { value = 100, unit = "Hz" }  # zero-phase Butterworth, order 4',
    'lowpass = { value = 100, unit = "Hz" }\nnotch = { value = 50, unit = "Hz" }').replace(
    'bias = { first = { value = 0.5, unit = "s" } }    # mean of the first 0.5 s subtracted',
    'bias = { first = { value = 0.5, unit = "s" }, last = { value = 0.5, unit = "s" } }\nrectify = true') + \
    '[reject]\ntarget = { value = 0.5, unit = "N" }\n'


def write(tmp_path, text, name="rig.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_issue_rig_parsed_verbatim(tmp_path):
    rig = load_rig(write(tmp_path, ISSUE_RIG))
    assert rig.format == "mat" and rig.variable == "data" and rig.sample_rate == 10000
    assert rig.channel("tangential_force").factor == pytest.approx(0.4444)
    assert rig.channel("position").factor == pytest.approx(0.0005e-3)  # count -> m
    assert rig.channel("normal_force").bias_first == 0.5
    assert (rig.lowpass, rig.order, rig.speed_above, rig.normal_force_above, rig.trim, rig.min_duration) == \
        (100, 4, pytest.approx(0.02), 0.05, 0.1, 0.3)


@pytest.mark.parametrize(("old", "new", "match"), [
    ('gain = { value = 0.31, unit = "N/V" }', 'gain = { value = 0.31, unit = "N/m" }',
     r"rig.toml: strokes.normal: channel 'normal_force' is not a force"),
    ('format = "mat"', 'format = "xls"', r"rig.toml: format: expected one of mat, hdf5, csv"),
    ('[filter]', '[filter]\nhighpass = 3', r"rig.toml: filter.highpass: unknown key \(expected one of lowpass,"),
    ('speed_above = { value = 20, unit = "mm/s" }', 'speed_above = { value = 20, unit = "mm" }',
     r"rig.toml: strokes.speed_above.unit: unit 'mm' is a length; expected a velocity"),
    ('unit = "count"', 'unit = "counts"', r"rig.toml: channels.position.unit: unknown unit 'counts'"),
    ('schema_version = 1\n', 'schema_version = 1\nfromat = "mat"\n', r"rig.toml: fromat: unknown key"),
])
def test_rig_errors_one_line(tmp_path, old, new, match):
    with pytest.raises(InputError, match=match) as info:
        load_rig(write(tmp_path, ISSUE_RIG.replace(old, new)))
    assert "\n" not in str(info.value)


def _trials(tmp_path, rng, n_trials, off_target=(), writer="v5"):
    truth = {}
    files = []
    for k in range(n_trials):
        lengths = rng.uniform(0.5, 1.5, 6)
        normal = 0.7 if k in off_target else 0.5
        sig, strokes = stroke_recording(rng, lengths=lengths, normal=normal)
        matrix = rig_volts(sig, bias=tuple(rng.uniform(0.1, 0.5, 2)))
        path = tmp_path / f"S{k % 3}_{50 * (k % 4)}V_{k}.mat"
        if writer == "v5":
            scipy.io.savemat(path, {"data": matrix})
        else:
            write_mat_v73(path, "data", matrix)
        truth[path.stem] = strokes
        files.append(path)
    return files, truth


@pytest.mark.parametrize("writer", ["v5", "v73"])
def test_strokes_found_and_calibrated(tmp_path, writer):
    rng = np.random.default_rng(41)
    files, truth = _trials(tmp_path, rng, 10 if writer == "v5" else 3, off_target=(2,), writer=writer)
    ing = run_ingest(files, write(tmp_path, RIG), tmp_path / "out")
    by = {r.name: r for r in ing.trials}
    for name, strokes in truth.items():
        assert len(by[name].strokes) == len(strokes)  # every stroke found, none invented
    assert not by[files[2].stem].kept and "% off the target 0.5 N (tolerance 15%)" in by[files[2].stem].reason
    frame = ing.dataset.frame
    assert files[2].stem not in set(frame.recording)
    z = []
    for name, group in frame.groupby("recording"):
        t = truth[name]
        assert list(group.direction) == [s["direction"] for s in t]
        assert np.allclose(group.start_time, [s["start"] + 0.05 / 2 + 0.1 for s in t], atol=0.02)
        for col in ("normal_force", "tangential_force"):
            z += list((group[col].to_numpy() - [s[col] for s in t]) / group[f"{col}_se"].to_numpy())
        assert (group.voltage == 50.0 * (int(name.split("_")[-1]) % 4)).all()
    z = np.array(z)
    if writer == "v5":  # 108 z-scores (normal and tangential of 54 strokes): N(0, 1) within sampling error
        assert abs(z.mean()) < 0.35 and 0.75 < z.std() < 1.3, (z.mean(), z.std())
    assert np.all(np.abs(z) < 4.5)
    trials = (tmp_path / "out" / "trials.csv").read_text()
    assert "rejected" in trials and "off the target" in trials


def test_dataset_card_records_inputs(tmp_path):
    rng = np.random.default_rng(7)
    files, _ = _trials(tmp_path, rng, 2)
    rig = write(tmp_path, RIG)
    ds = skinfit.ingest(files, rig, out=tmp_path / "out")
    assert {"normal_force_se", "tangential_force_se", "n_eff", "speed", "direction"} <= set(ds.frame.columns)
    p = ds.provenance
    assert p["raw_sha256"] == [hashlib.sha256(f.read_bytes()).hexdigest() for f in files]
    assert p["rig_sha256"] == hashlib.sha256(rig.read_bytes()).hexdigest() and p["rig_text"] == rig.read_text()
    assert any("Butterworth order 4" in line for line in p["pipeline"])
    again = skinfit.load_dataset(tmp_path / "out", model="electroadhesion_empirical")
    assert len(again) == len(ds) == 12


def test_hdf5_slow_position_and_newtons(tmp_path):
    """HDF5 layout /trials/<name>/<channel>, forces already in N, position sampled at 1 kHz."""
    rng = np.random.default_rng(5)
    truth = {}
    with h5py.File(tmp_path / "session.h5", "w") as fh:
        for k in range(2):
            sig, strokes = stroke_recording(rng)
            g = fh.create_group(f"trials/t{k}")
            g.attrs["sample_rate_hz"] = 10000.0
            g.attrs["subject"] = "S1"
            g.attrs["load"] = 500.0  # mN, declared under [metadata]
            g["fx"] = sig["tangential_force"] + 0.1
            g["fz"] = sig["normal_force"] + 0.05
            g["x"] = sig["position"][::10] * 1e3  # mm at 1 kHz
            g["x"].attrs["sample_rate_hz"] = 1000.0
            truth[f"session/t{k}"] = strokes
    rig = write(tmp_path, """schema_version = 1
format = "hdf5"
[metadata.load]
unit = "mN"
[channels.tangential_force]
dataset = "fx"
unit = "N"
bias = { first = { value = 0.5, unit = "s" }, last = { value = 0.5, unit = "s" } }
rectify = true
[channels.normal_force]
dataset = "fz"
unit = "N"
bias = { first = { value = 0.5, unit = "s" } }
[channels.position]
dataset = "x"
unit = "mm"
[filter]
lowpass = { value = 100, unit = "Hz" }
notch = [{ value = 50, unit = "Hz" }]
[strokes]
speed_above = { value = 20, unit = "mm/s" }
normal_force_above = { value = 0.05, unit = "N" }
trim = { value = 0.1, unit = "s" }
min_duration = { value = 0.3, unit = "s" }
""")
    ing = run_ingest([tmp_path / "session.h5"], rig)
    frame = ing.dataset.frame
    assert len(frame) == 12 and set(frame.subject) == {"S1"} and set(frame.load) == {0.5}
    for name, group in frame.groupby("recording"):
        want = np.array([s["tangential_force"] for s in truth[name]])
        assert np.all(np.abs(group.tangential_force.to_numpy() - want) < 5 * group.tangential_force_se.to_numpy())
        assert np.allclose(group.speed, 0.04, rtol=0.02)


@pytest.mark.parametrize("k", [3, 6])
def test_calibration_matrix_and_csv(tmp_path, k):
    """k gauges through a k x k matrix (a 90-degree mounting rotation about z) from a CSV with a time column."""
    rng = np.random.default_rng(9)
    sig, strokes = stroke_recording(rng, rate=5000.0, lengths=(0.8, 0.9, 1.0), drift=0.0)
    cal = np.eye(k) + 0.05 * rng.normal(size=(k, k))
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    n = len(sig["t"])
    sensor = np.zeros((k, n))
    sensor[:3] = rot.T @ np.vstack([sig["tangential_force"], np.zeros(n), sig["normal_force"]])  # sensor frame
    gauges = np.linalg.solve(cal, sensor) + 0.2  # volts with an offset
    header = ",".join(["time", *(f"g{i}" for i in range(k)), "x_mm"])
    outputs = ["tangential_force", "fy", "normal_force", "tx", "ty", "tz"][:k]
    table = np.column_stack([sig["t"], gauges.T, sig["position"] * 1e3])
    np.savetxt(tmp_path / "run.csv", table, delimiter=",", header=header, comments="")
    rig = write(tmp_path, f"""schema_version = 1
format = "csv"
time_column = "time"
{"".join(f'[channels.g{i}]{chr(10)}column = "g{i}"{chr(10)}unit = "V"{chr(10)}'
         f'bias = {{ first = {{ value = 0.5, unit = "s" }} }}{chr(10)}' for i in range(k))}
[channels.position]
column = "x_mm"
unit = "mm"
[calibration]
inputs = {[f"g{i}" for i in range(k)]}
outputs = {outputs}
unit = "N/V"
matrix = {cal.tolist()}
rotation = {rot.tolist()}
[filter]
lowpass = {{ value = 100, unit = "Hz" }}
notch = {{ value = 50, unit = "Hz" }}
[strokes]
speed_above = {{ value = 20, unit = "mm/s" }}
normal_force_above = {{ value = 0.05, unit = "N" }}
trim = {{ value = 0.1, unit = "s" }}
min_duration = {{ value = 0.3, unit = "s" }}
""")
    frame = run_ingest([tmp_path / "run.csv"], rig).dataset.frame
    assert len(frame) == 3
    want = np.array([s["normal_force"] for s in strokes])
    assert np.all(np.abs(frame.normal_force.to_numpy() - want) < 5 * frame.normal_force_se.to_numpy())
    sign = np.where(frame.direction == "forward", 1, -1)
    want = sign * np.array([s["tangential_force"] for s in strokes])
    assert np.all(np.abs(frame.tangential_force.to_numpy() - want) < 5 * frame.tangential_force_se.to_numpy())


def test_short_stroke_dropped_with_reason(tmp_path):
    rng = np.random.default_rng(11)
    sig, _ = stroke_recording(rng, lengths=(0.8, 0.25, 0.9))
    scipy.io.savemat(tmp_path / "S1_0V_1.mat", {"data": rig_volts(sig)})
    ing = run_ingest([tmp_path / "S1_0V_1.mat"], write(tmp_path, ISSUE_RIG))
    (trial,) = ing.trials
    assert len(trial.strokes) == 3 and len(trial.rows) == 2
    assert "shorter than min_duration 0.3 s" in trial.strokes[1]["reason"]


def test_file_errors_one_line(tmp_path):
    rig = write(tmp_path, ISSUE_RIG)
    scipy.io.savemat(tmp_path / "S1_0V_1.mat", {"other": np.zeros((10, 3))})
    with pytest.raises(InputError, match=r"S1_0V_1.mat: variable: has no numeric matrix 'data' \(found other\)"):
        run_ingest([tmp_path / "S1_0V_1.mat"], rig)
    scipy.io.savemat(tmp_path / "bad.mat", {"data": np.zeros((10, 3))})
    with pytest.raises(InputError, match=r"bad.mat: pattern: file name does not match"):
        run_ingest([tmp_path / "bad.mat"], rig)
    matrix = np.zeros((10, 3))
    matrix[7, 1] = np.nan
    scipy.io.savemat(tmp_path / "S1_0V_3.mat", {"data": matrix})
    with pytest.raises(InputError, match=r"S1_0V_3.mat: channel 'normal_force': sample 7 \(0-based, at 0.0007 s\) is "
                       r"nan: expected finite numbers"):
        run_ingest([tmp_path / "S1_0V_3.mat"], rig)
    scipy.io.savemat(tmp_path / "S1_0V_2.mat", {"data": np.zeros((10, 2))})
    with pytest.raises(InputError, match=r"S1_0V_2.mat: has 2 columns; channels.position.column = 2"):
        run_ingest([tmp_path / "S1_0V_2.mat"], rig)


@pytest.mark.filterwarnings("ignore::skinfit.errors.ConvergenceWarning")  # a short fit: only the reading is checked
def test_cli_review_and_fit(tmp_path, capsys):
    """`skinfit ingest ... --review` writes the dataset and the page; `skinfit.fit` reads the folder."""
    rng = np.random.default_rng(3)
    files, _ = _trials(tmp_path, rng, 3, off_target=(1,))
    out = tmp_path / "ds"
    assert main(["ingest", *map(str, files), "--rig", str(write(tmp_path, RIG)), "--out", str(out), "--review"]) == 0
    text = capsys.readouterr().out
    assert "12 strokes from 2 of 3 trial(s)" in text and f"rejected {files[1].stem}: mean normal_force" in text
    page = (out / "review" / "index.html").read_text()
    assert page.count("<img") == 3 and "rejected: mean normal_force" in page
    assert main(["ingest", str(files[0]), "--rig", str(tmp_path / "rig.toml"), "--out", str(out)]) == 2
    assert "holds a dataset already (pass --overwrite" in capsys.readouterr().err
    fit = skinfit.fit("electroadhesion_empirical", out, rng=1, max_steps=150, ess_target=20, n_global=100)
    assert fit.idata["observed_data"]["tangential_force"].size == 12


def test_chunks_join_into_the_whole_recording_filtered(tmp_path):
    """Filtering by 0.3 s chunks (strokes carried across chunk ends) gives the rows of one chunk."""
    rng = np.random.default_rng(13)
    sig, _ = stroke_recording(rng)
    scipy.io.savemat(tmp_path / "S1_0V_1.mat", {"data": rig_volts(sig)})
    rig = write(tmp_path, ISSUE_RIG)
    whole = run_ingest([tmp_path / "S1_0V_1.mat"], rig, chunk_seconds=1000).dataset.frame
    chunked = run_ingest([tmp_path / "S1_0V_1.mat"], rig, chunk_seconds=0.3).dataset.frame
    assert len(whole) == 6
    for col in ("normal_force", "tangential_force", "speed", "start_time", "duration"):
        np.testing.assert_allclose(chunked[col], whole[col], rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(chunked.normal_force_se, whole.normal_force_se, rtol=1e-3)


@pytest.mark.parametrize("transposed", [False, True])
def test_hdf5_matrix_dataset_reads_as_the_mat_file(tmp_path, transposed):
    """Channels as columns of one 2-D HDF5 dataset per trial (samples x channels, or channels x
    samples as MATLAB's h5write leaves it) give the rows the same matrix gives from a .mat file."""
    rng = np.random.default_rng(17)
    sig, _ = stroke_recording(rng)
    matrix = rig_volts(sig)
    scipy.io.savemat(tmp_path / "S1_0V_1.mat", {"data": matrix})
    with h5py.File(tmp_path / "S1_0V_1.h5", "w") as fh:
        fh.create_group("trials/one").attrs["sample_rate_hz"] = 10000.0
        fh["trials/one/voltages"] = matrix.T if transposed else matrix
    text = ISSUE_RIG.replace('format = "mat"', 'format = "hdf5"').replace('variable = "data"', "")
    text = text.replace("column = ", 'dataset = "voltages"\ncolumn = ').replace("pattern = ", "# pattern = ")
    with pytest.raises(InputError, match=r"S1_0V_1.h5: metadata.voltage: trial S1_0V_1/one has no value for metadata "
                       r"'voltage' declared in the rig file"):
        run_ingest([tmp_path / "S1_0V_1.h5"], write(tmp_path, text, "h5rig.toml"))
    text = text.replace("[metadata.voltage]", "[metadata.voltage]\nvalue = 0")
    h5 = run_ingest([tmp_path / "S1_0V_1.h5"], write(tmp_path, text, "h5rig.toml")).dataset.frame
    mat = run_ingest([tmp_path / "S1_0V_1.mat"], write(tmp_path, ISSUE_RIG)).dataset.frame
    assert len(h5) == len(mat) == 6
    for col in ("normal_force", "tangential_force", "normal_force_se", "speed", "start_time"):
        np.testing.assert_allclose(h5[col], mat[col], rtol=1e-12)


def test_every_trial_rejected_review_still_written(tmp_path, capsys):
    """All trials off target: the review page and trials.csv are written, then one line names the
    page and the command exits 2; an earlier run's dataset in the folder is removed, not left stale."""
    rng = np.random.default_rng(23)
    files, _ = _trials(tmp_path, rng, 2, off_target=(0, 1))
    (tmp_path / "good").mkdir()
    good, _ = _trials(tmp_path / "good", rng, 1)
    rig = str(write(tmp_path, RIG))
    out = tmp_path / "ds"
    assert main(["ingest", str(good[0]), "--rig", rig, "--out", str(out)]) == 0
    assert (out / "dataset.toml").exists()
    assert main(["ingest", *map(str, files), "--rig", rig, "--out", str(out), "--review", "--overwrite"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "no trial kept, no dataset written: 2 of 2 trial(s) rejected (first: " in err
    assert f"review page {out / 'review' / 'index.html'} and in {out / 'trials.csv'}" in err
    page = (out / "review" / "index.html").read_text()
    assert "No trial kept: all 2 trial(s) rejected" in page and page.count("<img") == 2
    assert page.count("% off the target 0.5 N") >= 2
    assert (out / "trials.csv").read_text().count(",rejected,") == 2
    assert not (out / "dataset.toml").exists() and not (out / "data.csv").exists()
    # Python: the same error after the page; without review the reasons are in the message
    with pytest.raises(InputError, match=r"no trial kept.*review page .*index\.html") as info:
        skinfit.ingest(files, rig, out=tmp_path / "py", review=True)
    assert "\n" not in str(info.value) and (tmp_path / "py" / "review" / "index.html").exists()
    with pytest.raises(InputError, match=rf"no trial kept, no dataset written \({files[0].stem}: mean normal_force"):
        skinfit.ingest(files, rig)
    with pytest.raises(InputError, match=r"review: the review page is written into the dataset folder"):
        skinfit.ingest(files, rig, review=True)


def test_shared_bias_part_of_the_standard_error(tmp_path):
    """``normal_force_se_bias`` is the se of the bias subtracted (mean of the first 0.5 s, shared
    by the trial's strokes): calibrated against the bias's actual error, computed from the
    simulated truth (the at-rest samples' mean), and the remaining part against each stroke's own
    error; with 0.5 s of bias and ~1 s strokes the shared part is most of the variance."""
    rng = np.random.default_rng(29)
    files, truth, bias_err = [], {}, {}
    for k in range(14):
        sig, strokes = stroke_recording(rng, lengths=rng.uniform(0.5, 1.5, 6))
        path = tmp_path / f"S1_0V_{k}.mat"
        scipy.io.savemat(path, {"data": rig_volts(sig)})
        files.append(path)
        truth[path.stem] = np.array([s["normal_force"] for s in strokes])
        bias_err[path.stem] = np.mean(sig["normal_force"][:5000])  # finger off: all of it is the bias's error
    ing = run_ingest(files, write(tmp_path, RIG.split("[reject]")[0]))
    frame = ing.dataset.frame
    z_bias, z_own, share = [], [], []
    for name, g in frame.groupby("recording"):
        se, se_bias = g.normal_force_se.to_numpy(), g.normal_force_se_bias.to_numpy()
        assert np.ptp(se_bias) == 0  # one bias per trial (first window only)
        z_bias.append(bias_err[name] / se_bias[0])
        own = g.normal_force.to_numpy() - truth[name] + bias_err[name]  # the stroke's error less the bias's
        z_own += list(own / np.sqrt(se**2 - se_bias**2))
        share += list(se_bias**2 / se**2)
    z_bias, z_own = np.array(z_bias), np.array(z_own)
    assert abs(z_bias.mean()) < 0.7 and 0.5 < z_bias.std() < 1.6, (z_bias.mean(), z_bias.std())  # 14 trials
    assert abs(z_own.mean()) < 0.45 and 0.75 < z_own.std() < 1.4, (z_own.mean(), z_own.std())  # 84 strokes
    assert 0.4 < np.median(share) < 0.8  # bench/results/ingest_bias_share.md: 0.60-0.63
    assert ing.dataset.column("normal_force_se_bias").unit == "N"
