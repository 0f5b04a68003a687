"""emcee, run until converged: vectorised ensemble, DE + snooker moves, walkers from the Laplace ball.

Moves measured on the shipped electroadhesion posterior (32 walkers, same seed): with emcee
3.1.6's own DESnookerMove the runs looked fast but sampled a too-narrow distribution (that
move underestimates variances by ~25% on a 5-D Gaussian; see skinfit/moves.py). With the
corrected snooker and the card's (phi, d_air) shear: DE 0.8 + snooker 0.2 converged in 11.6k
steps (tau_max 127, 25 s); DE 0.5 + snooker 0.5 in 14.5k (tau_max 155, 38 s). Without the
shear, 64 walkers needed 55k steps (tau_max 527).  With the card's (d_air shift, beta0
product) coordinates as well (skinfit/posterior.py), the same posterior mixes at tau_max
31-39 (DE 0.9 + snooker 0.1: 35; 0.8 + 0.2: 39; on a standard 8-D Gaussian DE alone gives
26), and converges in 2.7-3.9k steps (5 seeds), where the R-hat gate (~100 tau) binds.

Convergence (see NOTES: walkers are not independent chains): after discarding a burn-in of
``burn_factor`` integrated autocorrelation times, the kept chain must be at least
``min_tau_multiple`` (50) times the largest autocorrelation time, the effective sample size
``nwalkers * n_kept / tau`` must reach ``ess_target`` for every coordinate, and the
rank-normalised R-hat over walkers must be <= ``rhat_max`` (a secondary check).
"""

import time
import warnings
from dataclasses import dataclass

import arviz as az
import emcee
import numpy as np
from emcee.autocorr import auto_window

from .moves import default_moves

__all__ = ["SamplerRun", "run_emcee", "initial_ball", "check_points"]


@dataclass(frozen=True)
class SamplerRun:
    chain: np.ndarray  # kept, thinned samples in sampling coordinates, (nwalkers, ndraw, d)
    log_prob: np.ndarray  # (nwalkers, ndraw)
    tau: np.ndarray  # integrated autocorrelation time per coordinate [steps]
    ess_emcee: np.ndarray  # nwalkers * n_kept / tau
    rhat_max: float
    acceptance: np.ndarray  # per walker
    n_steps: int
    burn: int
    thin: int
    converged: bool
    reasons: tuple  # why not converged
    seconds: float
    evaluations: int


def initial_ball(post, z0, cov, nwalkers, rng, max_tries=20):
    """Walkers drawn from N(z0, cov); draws outside the support are redrawn, then shrunk."""
    chol = np.linalg.cholesky(cov)
    out = np.empty((nwalkers, len(z0)))
    need = np.arange(nwalkers)
    scale = 1.0
    for attempt in range(max_tries):
        cand = z0 + scale * rng.standard_normal((len(need), len(z0))) @ chol.T
        ok = np.isfinite(post(cand))
        out[need[ok]] = cand[ok]
        need = need[~ok]
        if len(need) == 0:
            return out
        if attempt >= 4:
            scale *= 0.5
    raise RuntimeError(f"could not place {len(need)} of {nwalkers} walkers inside the support around "
                       f"the MAP (outside the physical support: {post.counts['outside_support']} evaluations)")


def run_emcee(post, p0, rng, *, ess_target=400, rhat_max=1.01, min_tau_multiple=50,
              burn_factor=2.0, max_steps=20000, check_every=200, moves=None, progress=False,
              keep_total=4000, checkpoint=None, resume=None):
    """Run emcee from walkers ``p0`` (nwalkers, d) until converged or ``max_steps``.

    Convergence is checked at step counts fixed by ``check_every`` and ``max_steps`` alone
    (:func:`check_points`), never by wall time, and emcee's RandomState is seeded by one draw
    from ``rng``: the chain is a pure function of (``p0``, ``rng`` state, settings).
    ``checkpoint`` (a :class:`skinfit.checkpoint.Checkpoint`) is written when due, at the end
    and on KeyboardInterrupt; ``resume`` (a :class:`skinfit.checkpoint.Saved`) continues a
    checkpointed chain exactly where it stopped.
    """
    t0 = time.perf_counter()
    nwalkers, d = p0.shape
    moves = moves if moves is not None else default_moves()
    seed = int(rng.integers(2**32 - 1))
    backend, spent = emcee.backends.Backend(), 0.0
    state = emcee.State(p0, random_state=np.random.RandomState(seed).get_state())
    if resume is not None and resume.iteration > 0:
        backend.reset(nwalkers, d)
        backend.grow(resume.iteration, None)
        backend.chain[:], backend.log_prob[:] = resume.chain, resume.log_prob
        backend.accepted[:] = resume.accepted
        backend.iteration, backend.random_state = resume.iteration, resume.random_state
        state = emcee.State(resume.chain[-1], log_prob=resume.log_prob[-1], random_state=resume.random_state)
        spent = resume.seconds
        if hasattr(post, "counts"):
            post.counts.update(resume.counts)
    sampler = emcee.EnsembleSampler(nwalkers, d, post, vectorize=True, moves=moves, backend=backend)
    n = backend.iteration
    # the evaluation counters as of the last completed step (targets without them: none)
    counts = dict(getattr(post, "counts", {}))

    def save():
        if checkpoint is not None:
            checkpoint.write(chain=backend.get_chain(), log_prob=backend.get_log_prob(),
                             accepted=backend.accepted, random_state=backend.random_state or state.random_state,
                             counts=counts, seconds=spent + time.perf_counter() - t0)

    bar = _progress_bar(progress, max_steps)
    if bar is not None:
        bar.update(n)
    reasons = ("not run",)
    try:
        for target in check_points(check_every, max_steps):
            if target < n:
                continue
            if target > n:
                for state in sampler.sample(state, iterations=target - n):
                    counts = dict(getattr(post, "counts", {}))
                    if bar is not None:
                        bar.update(1)
                    if checkpoint is not None and checkpoint.due():
                        save()
                n = target
            tau, burn, ess, rhat, reasons = _check(sampler.get_chain(), ess_target, rhat_max,
                                                   min_tau_multiple, burn_factor,
                                                   need_rhat=target >= max_steps or bar is not None)
            if bar is not None:
                bar.set_postfix_str(f"tau={tau.max():.0f} ess={ess.min():.0f} rhat={rhat:.3f}")
            if not reasons:
                break
    except KeyboardInterrupt:
        save()
        raise
    finally:
        if bar is not None:
            bar.close()
    save()
    chain = sampler.get_chain()
    logp = sampler.get_log_prob()
    thin = max(1, int(np.ceil((chain.shape[0] - burn) * nwalkers / keep_total)))
    kept = chain[burn::thin].transpose(1, 0, 2)
    return SamplerRun(chain=kept, log_prob=logp[burn::thin].T, tau=tau, ess_emcee=ess, rhat_max=rhat,
                      acceptance=np.asarray(sampler.acceptance_fraction), n_steps=n, burn=burn,
                      thin=thin, converged=not reasons, reasons=tuple(reasons),
                      seconds=spent + time.perf_counter() - t0, evaluations=n * nwalkers)


def check_points(check_every, max_steps):
    """Step counts at which convergence is checked: every ``check_every`` steps, the interval
    growing to a tenth of the chain length, the last at ``max_steps`` (electroadhesion: 14
    checks, 0.63 s of 5.8 s of sampling, profiled)."""
    n = 0
    while n < max_steps:
        n = min(n + check_every, max_steps)
        yield n
        check_every = max(check_every, int(0.1 * n))


def _check(chain, ess_target, rhat_max, min_tau_multiple, burn_factor, need_rhat=False):
    """Convergence gate on the chain so far, a pure function of it.  One autocorrelation
    estimate, on the last three quarters, sets both the burn-in (``burn_factor`` x tau, at
    most half the chain) and the effective sample size of the kept steps.  R-hat (the costlier
    part) is computed only when the other criteria pass, or when ``need_rhat``."""
    n, nwalkers, d = chain.shape
    tau = integrated_time(chain[n // 4:])
    burn = min(n // 2, int(np.ceil(burn_factor * tau.max())))
    kept = chain[burn:]
    n_kept = kept.shape[0]
    ess = nwalkers * n_kept / tau
    reasons = []
    if n_kept < min_tau_multiple * tau.max():
        reasons.append(f"chain of {n_kept} kept steps < {min_tau_multiple} x tau = {min_tau_multiple * tau.max():.0f}")
    if ess.min() < ess_target:
        reasons.append(f"min ESS {ess.min():.0f} < {ess_target}")
    rhat = float("nan")
    if need_rhat or not reasons:
        step = max(1, int(tau.min() / 2))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rhat = float(np.max(az.rhat(kept[::step].transpose(1, 0, 2), chain_axis=0, draw_axis=1)))
        if not rhat <= rhat_max:
            reasons.append(f"max R-hat {rhat:.3f} > {rhat_max}")
    return tau, burn, ess, rhat, reasons


def integrated_time(x, c=5):
    """emcee's ``integrated_time(x, c, tol=0)`` for x (steps, walkers, d), same estimator and
    window, with one batched real FFT per coordinate instead of a Python loop of complex FFTs
    over walkers (3.4x faster on (20000, 32, 8); equal to 1e-15)."""
    n = x.shape[0]
    size = 2 * (1 << (n - 1).bit_length())  # emcee: 2 * next_pow_two(n)
    tau = np.empty(x.shape[2])
    for j in range(x.shape[2]):
        f = np.fft.rfft(x[:, :, j] - x[:, :, j].mean(axis=0), n=size, axis=0)
        acf = np.fft.irfft(f.real**2 + f.imag**2, n=size, axis=0)[:n]
        taus = 2.0 * np.cumsum((acf / acf[0]).mean(axis=1)) - 1.0
        tau[j] = taus[auto_window(taus, c)]
    return tau


def _progress_bar(progress, total):
    if not progress:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, desc="emcee", unit="step", leave=False, mininterval=0.5)
