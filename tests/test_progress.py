"""What a sampling run shows while it runs (skinfit.inference.progress): steps against the next
convergence check, never against max_steps; without a terminal one line per check, no ``\\r``."""

import io
import re
import warnings

import numpy as np

import skinfit
from skinfit.inference.progress import Progress


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def _run(stream):
    """Two checks of a made-up run (at steps 50 and 100, the second converged) on ``stream``."""
    p = Progress(400, stream)
    p.start(0, 50)
    for _ in range(50):
        p.step()
    p.check(50, np.array([3.0, 9.5]), np.array([120.0, 700.0]), float("nan"), ["min ESS 120 < 400"], 100)
    for _ in range(50):
        p.step()
    p.check(100, np.array([3.0, 4.2]), np.array([450.0, 900.0]), 1.004, [], None)
    p.close()
    return stream.getvalue()


def test_without_a_terminal_one_line_per_check_and_no_carriage_return():
    text = _run(io.StringIO())
    assert "\r" not in text
    assert text.splitlines() == [
        "emcee: sampling from step 0; first convergence check at step 50",
        "emcee: check 1 at step 50: min ESS 120 of 400, max tau 9.5 steps; next check at step 100",
        "emcee: check 2 at step 100: min ESS 450 of 400, max tau 4.2 steps, R-hat 1.004; converged"]


def test_on_a_terminal_the_bar_counts_to_the_next_check():
    text = _run(_Terminal())
    frames = text.split("\r")
    assert len(frames) > 2
    totals = {int(m) for m in re.findall(r"\d+/(\d+)", text)}
    assert totals == {50, 100}, totals  # the first check, then the second: never a max_steps
    assert "min ESS 120 of 400" in text and "to check 2" in text


def test_a_fit_with_progress_and_no_terminal_logs_its_checks(capsys):
    """A fit's own run (pytest's captured stderr is no terminal): one line per check, the steps
    those of the checks it made, the last at the step where it stopped."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        fit = skinfit.fit("electroadhesion", "electroadhesion_synthetic", max_steps=400, n_global=300, rng=4,
                          progress=True, complete=False)
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = [line for line in err.splitlines() if line.startswith("emcee: check")]
    steps = [int(re.search(r"at step (\d+)", line).group(1)) for line in lines]
    assert steps == sorted(steps) and steps[-1] == fit.attr("sampler")["n_steps"]
    assert ("converged" in lines[-1]) == fit.converged
    assert all("of 400" in line for line in lines)
