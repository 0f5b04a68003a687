"""Checkpoint and resume: a fit killed with SIGKILL and resumed equals an uninterrupted run;
saves are atomic; a checkpoint of other inputs is refused."""

import os
import re
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

import skinfit
from skinfit.errors import InputError
from skinfit.inference.checkpoint import Checkpoint, load_checkpoint
from skinfit.inference.optimize import MAPResult, laplace_covariance
from skinfit.inference.proposal import MixtureT
from skinfit.inference.sampling import check_points, initial_ball, run_emcee
from skinfit.io.arguments import as_generator
from skinfit.posterior import Posterior

ROOT = Path(skinfit.__file__).resolve().parents[1]
MODEL, DATA = "electroadhesion_coulomb", "electroadhesion_synthetic"
# an ESS target no run reaches: every run goes to max_steps (the longest, most exposed case)
ARGS = ["--seed", "5", "--ess", "1e9", "--max-steps", "2500", "--quiet"]


def _cli(out, *extra):
    return [sys.executable, "-m", "skinfit", "fit", MODEL, DATA, "--out", str(out), *ARGS, *extra]


def _run(cmd):
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return proc


def _assert_same_samples(a, b):
    for group in ("posterior", "sample_stats", "posterior_predictive", "prior"):
        x, y = a.idata[group].to_dataset(), b.idata[group].to_dataset()
        for v in x.data_vars:
            if v != "acceptance":
                assert np.array_equal(x[v].values, y[v].values), f"{group}/{v} differs"
    assert np.array_equal(a.idata["sample_stats"]["acceptance"].values, b.idata["sample_stats"]["acceptance"].values)
    sa, sb = a.attr("sampler"), b.attr("sampler")
    assert sa["n_steps"] == sb["n_steps"] and sa["tau"] == sb["tau"]
    assert a.attr("support_counts") == b.attr("support_counts")
    assert a.map == b.map


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("reference")
    _run(_cli(out))
    return skinfit.load_fit(out)


def test_sigkill_then_resume_equals_uninterrupted_run(reference, tmp_path):
    proc = subprocess.Popen(_cli(tmp_path, "--checkpoint-every", "0.3"), cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ckpt = tmp_path / "checkpoint.h5"
    t0 = time.monotonic()
    while not ckpt.exists() and proc.poll() is None and time.monotonic() - t0 < 300:
        time.sleep(0.05)
    time.sleep(0.2)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    saved = load_checkpoint(ckpt)
    assert 0 < saved.iteration < 2500, "the kill must land mid-run"
    assert not (tmp_path / "fit.nc").exists()
    out = _run(_cli(tmp_path, "--resume"))
    assert "starting afresh" not in out.stderr
    _assert_same_samples(reference, skinfit.load_fit(tmp_path))


@pytest.mark.parametrize("adaptive, stop_after", [(False, 720), (True, 400)], ids=["de-moves", "adaptive"])
def test_resume_after_interrupt_inside_a_step_mid_interval(adaptive, stop_after):
    """A KeyboardInterrupt raised inside a log-density evaluation, between convergence checks:
    the checkpoint holds the last completed step, and resuming reproduces the full chain.  With
    the adaptive independence proposal the interrupt lands after the refit steps 50, 100 and 200,
    which the resumed run recomputes from the saved chain."""
    post = Posterior(skinfit.load_model(MODEL), skinfit.load_priors(MODEL), skinfit.load_dataset(DATA))

    class Interrupting:
        def __init__(self, stop_after):
            self.left, self.counts = stop_after, post.counts

        def __call__(self, z):
            self.left -= 1
            if self.left < 0:
                raise KeyboardInterrupt
            return post(z)

    rng = as_generator(11)
    z = post.to_z(post.sample_prior(32, rng))
    proposal = None
    if adaptive:
        theta = post.sample_prior(400, rng)
        z0 = post.to_z(theta[np.argmax(post.log_density(theta))][None])[0]
        proposal = MixtureT([1.0], z0[None], laplace_covariance(post, z0)[None])
        z = initial_ball(post, z0, laplace_covariance(post, z0), 16, rng)
    kw = dict(ess_target=1e9, max_steps=700, check_every=200, proposal=proposal)
    state = rng.bit_generator.state
    full = run_emcee(post, z, rng, **kw)
    path = Path(os.environ.get("TMPDIR", "/tmp")) / f"skinfit-ckpt-{os.getpid()}.h5"
    ckpt = Checkpoint(path, {"format": 1}, interval=1e9)
    rng.bit_generator.state = state
    ckpt.start(z, state, MAPResult(np.zeros(4), 0.0, (), 0, 0.0), proposal or MixtureT([1.0], np.zeros((1, 4)), np.eye(4)[None]))
    with pytest.raises(KeyboardInterrupt):
        run_emcee(Interrupting(stop_after), z, rng, checkpoint=ckpt, **kw)  # ~2 (DE) or 1-2 evaluations a step
    saved = load_checkpoint(path)
    path.unlink()
    assert 200 < saved.iteration < 400 and saved.iteration not in set(check_points(200, 700))
    rng = as_generator(0)  # any: the random states come from the checkpoint
    rng.bit_generator.state = saved.generator_state
    resumed = run_emcee(post, saved.p0, rng, resume=saved, **kw)
    assert [a["step"] for a in resumed.adaptation] == [a["step"] for a in full.adaptation]
    assert not adaptive or any(a["refit"] for a in full.adaptation)
    assert np.array_equal(resumed.chain, full.chain) and np.array_equal(resumed.log_prob, full.log_prob)
    assert np.array_equal(resumed.acceptance, full.acceptance) and resumed.n_steps == full.n_steps == 700
    assert resumed.evaluations == full.evaluations  # counted across the interrupt (1 to 3 a walker and step)


def test_check_points_do_not_depend_on_time():
    assert list(check_points(200, 4000)) == [200, 400, 600, 800, 1000, 1200, 1400, 1600, 1800, 2000,
                                             2200, 2420, 2662, 2928, 3220, 3542, 3896, 4000]


@pytest.fixture(scope="module")
def small_checkpoint(tmp_path_factory):
    path = tmp_path_factory.mktemp("small") / "checkpoint.h5"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        skinfit.fit(MODEL, DATA, rng=2, ess_target=50, max_steps=200, n_global=200, checkpoint=path)
    return path


def _resume(path, **kw):
    args = dict(rng=2, ess_target=50, max_steps=200, n_global=200)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        return skinfit.fit(kw.pop("model", MODEL), kw.pop("dataset", DATA), checkpoint=path, resume=True,
                           **(args | kw))


def test_refused_when_dataset_changed(small_checkpoint):
    ds = skinfit.load_dataset(DATA)
    with pytest.raises(InputError, match=r"cannot resume: dataset changed \(electroadhesion_synthetic"):
        _resume(small_checkpoint, dataset=ds.subset(ds.frame["voltage"] > 0, "voltage>0"))


def test_refused_when_prior_file_changed(small_checkpoint, tmp_path):
    text = (ROOT / "priors" / f"{MODEL}.toml").read_text().replace("scale = 0.3", "scale = 0.4")
    (tmp_path / "p.toml").write_text(text)
    with pytest.raises(InputError, match=r"prior file changed.*priors changed for mu"):
        _resume(small_checkpoint, priors=skinfit.load_priors(tmp_path / "p.toml"))


def test_refused_when_parameter_order_changed(small_checkpoint, tmp_path):
    card = (ROOT / "models" / f"{MODEL}.toml").read_text()
    mu = card[card.index("[[parameters]]\nname = \"mu\""):card.index("[[parameters]]\nname = \"E_star\"")]
    card = card.replace(mu, "").replace("[constants]", mu + "[constants]")
    (tmp_path / f"{MODEL}.toml").write_text(card)
    model = skinfit.load_model(tmp_path / f"{MODEL}.toml")
    assert model.parameter_names == ("E_star", "d_air", "mu")
    with pytest.raises(InputError, match=r"parameter order differs: checkpoint has \['mu', 'E_star', "
                                         r"'d_air', 'sigma'\], now \['E_star', 'd_air', 'mu', 'sigma'\]"):
        _resume(small_checkpoint, model=model)


def test_refused_when_settings_or_seed_changed(small_checkpoint):
    with pytest.raises(InputError, match=r"setting ess_target differs: checkpoint 50, now 60"):
        _resume(small_checkpoint, ess_target=60)
    with pytest.raises(InputError, match=r"seed differs: checkpoint 2, now 3"):
        _resume(small_checkpoint, rng=3)


def test_resumed_fit_reports_its_timings_as_resumed(small_checkpoint):
    """A resumed fit ran no MAP or start itself: its wall-time line says so instead of printing
    the first run's MAP minus this call's start (-0.08 s before the fix)."""
    saved = load_checkpoint(small_checkpoint)
    fit = _resume(small_checkpoint)
    t = fit.attr("timings")
    assert t["resumed"] and t["start_s"] == 0.0 and t["map_s"] == saved.map["seconds"]
    assert t["sampling_s"] >= saved.seconds  # every run's sampling
    line = next(x for x in fit.report_text().splitlines() if x.startswith("wall time"))
    assert line.startswith(f"wall time: resumed from a checkpoint (MAP {saved.map['seconds']:.2f} s in the first run)")
    assert not re.search(r"-\d", line)  # no negative time


def test_garbage_checkpoint_is_an_input_error(tmp_path):
    (tmp_path / "checkpoint.h5").write_bytes(b"\x89HDF\r\n\x1a\n truncated")
    with pytest.raises(InputError, match="not a readable skinfit checkpoint"):
        load_checkpoint(tmp_path / "checkpoint.h5")


_SAVER = """
import sys, skinfit
fit = skinfit.load_fit(sys.argv[1])
for i in range(10**6):
    fit.idata.attrs["generation"] = i
    fit.save(sys.argv[2])
    print(i, flush=True)
"""


@pytest.mark.parametrize("delay", [0.0, 0.07, 0.13])
def test_killed_save_leaves_old_or_new_file(reference, tmp_path, delay):
    src, dst = tmp_path / "src.nc", tmp_path / "fit.nc"
    reference.save(src)
    proc = subprocess.Popen([sys.executable, "-c", _SAVER, str(src), str(dst)], cwd=ROOT,
                            stdout=subprocess.PIPE, text=True)
    done = [int(proc.stdout.readline()) for _ in range(2)]
    time.sleep(delay)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done += [int(line) for line in proc.stdout.read().split()]
    loaded = skinfit.load_fit(dst)
    # the last completed save, or the one in flight (renamed before the kill, not yet printed)
    assert loaded.idata.attrs["generation"] in (done[-1], done[-1] + 1)
    assert np.array_equal(loaded.idata["posterior"]["mu"].values, reference.idata["posterior"]["mu"].values)


# ---- issue 21, class 2: killed saves leave no file behind; one writer per folder --------------------
def test_class2_stale_temp_files_removed_only_when_their_writer_is_dead(tmp_path):
    from skinfit.inference.checkpoint import _host, remove_stale_temps, temp_file

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        group = tmp_path / "m" / "d" / "g"
        group.mkdir(parents=True)
        mine = Path(temp_file(group / "fit.nc"))  # this process: alive
        assert mine.name.startswith(f".fit.nc.{_host()}.{os.getpid()}-") and mine.name.endswith(".tmp")
        assert Path(temp_file(group / "fit.nc")) != mine  # unique per write
        stale = group / f".fit.nc.{_host()}.{dead.pid}-abc12345.tmp"
        running = group / f".fit.nc.{_host()}.{live.pid}-abc12345.tmp"
        elsewhere = group / f".fit.nc.otherhost.{dead.pid}-abc12345.tmp"
        foreign = group / "notes.tmp"
        for p in (stale, running, elsewhere, foreign):
            p.write_text("partial")
        assert remove_stale_temps(tmp_path) == [stale]
        assert all(p.exists() for p in (mine, running, elsewhere, foreign)) and not stale.exists()
    finally:
        live.kill()
        live.wait()


def test_class2_lock_names_the_pid_holding_the_folder(tmp_path):
    from skinfit.inference.checkpoint import CheckpointLock

    code = ("import sys, time; from skinfit.inference.checkpoint import CheckpointLock\n"
            f"with CheckpointLock({str(tmp_path / 'checkpoint.h5')!r}):\n"
            "    print('held', flush=True); time.sleep(60)\n")
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(InputError, match=rf"^{tmp_path}: is in use by pid {holder.pid} \(lock "):
            with CheckpointLock(tmp_path / "checkpoint.h5"):
                pass
    finally:
        holder.kill()
        holder.wait()
    with CheckpointLock(tmp_path / "checkpoint.h5"):  # released by the kernel when its holder died
        pass
