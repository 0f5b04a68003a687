"""What a sampling run shows while it runs: its steps against its next convergence check.

A run stops at the first check it passes (:func:`skinfit.inference.sampling.run_emcee`), not at
``max_steps``, so a bar over ``max_steps`` promises minutes for a run that ends at step 150.
On a terminal, :class:`Progress` shows a bar up to the next check, and after each check what it
found (the smallest effective sample size against its target, the largest autocorrelation time,
R-hat); elsewhere (a log file, a pipe, a notebook's captured stream) it writes one line per
check instead of a bar redrawn with carriage returns.
"""

import sys

from tqdm.auto import tqdm

__all__ = ["Progress"]


class Progress:
    """Progress of one sampling run towards ``ess_target`` (the effective sample size every
    coordinate needs), written to ``stream`` (standard error by default): a tqdm bar when the
    stream is a terminal, else one line per convergence check."""

    def __init__(self, ess_target, stream=None):
        self.stream = sys.stderr if stream is None else stream
        self.ess_target = ess_target
        isatty = getattr(self.stream, "isatty", None)
        self.terminal = bool(isatty and isatty())
        self.bar = None
        self.checks = 0

    def start(self, step, target):
        """The run starts at ``step`` (0, or where a resumed run stopped); the first check is at
        step ``target``."""
        if self.terminal:
            self.bar = tqdm(total=target, initial=step, desc="emcee, to check 1", unit="step", leave=False,
                            file=self.stream, mininterval=0.5, dynamic_ncols=True)
        else:
            self._line(f"sampling from step {step}; first convergence check at step {target}")

    def step(self):
        """One more step sampled."""
        if self.bar is not None:
            self.bar.update(1)

    def check(self, step, tau, ess, rhat, reasons, following):
        """The check at ``step`` found autocorrelation times ``tau`` and effective sample sizes
        ``ess`` (per coordinate), R-hat ``rhat`` (NaN when not computed) and ``reasons`` why
        the run has not converged (none: it has); the next check is at step ``following``
        (None: there is none, the run stops)."""
        self.checks += 1
        found = (f"min ESS {ess.min():.0f} of {self.ess_target:g}, max tau {tau.max():.1f} steps"
                 + (f", R-hat {rhat:.3f}" if rhat == rhat else ""))
        if not reasons:
            verdict = "converged"
        elif following is None:
            verdict = "stopped at max_steps, not converged: " + "; ".join(reasons)
        else:
            verdict = f"next check at step {following}"
        if self.bar is not None:
            self.bar.set_postfix_str(found, refresh=False)
            if following is not None and reasons:
                self.bar.total = following
                self.bar.set_description_str(f"emcee, to check {self.checks + 1}", refresh=False)
            self.bar.refresh()
        else:
            self._line(f"check {self.checks} at step {step}: {found}; {verdict}")

    def close(self):
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def _line(self, text):
        print(f"emcee: {text}", file=self.stream, flush=True)
