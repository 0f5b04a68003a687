"""emcee, run until converged: independence moves from an adaptive mixture proposal plus DE.

How a fit samples (:func:`skinfit.results.fit.start`, :func:`importance_start`, :func:`run_emcee`):

1. The Laplace approximation at the MAP, in sampling coordinates, as a Student-t (with a
   twice-as-wide component), is improved by population Monte Carlo: 2000 draws in one
   vectorised call, importance weights, a mixture refitted to the weighted draws, up to
   three rounds.  Where the weights are degenerate at first (a Hessian at a cusp of the log
   density gives a proposal far too narrow), the proposal is first refitted to tempered
   weights, widening it round by round until they are not.  The walkers are drawn from the
   weighted draws, so they start in the typical set.
2. emcee runs with :class:`~skinfit.inference.moves.IndependenceMove` (80% of steps: every walker
   makes three independence updates in a row from fresh draws of the mixture, all drawn and
   evaluated in one call for the whole ensemble) and :class:`~skinfit.inference.moves.DEMove` (20%:
   local mixing where the mixture fits poorly).
3. At step 50, then 100, 200, ... while the run has not converged (checked first), the
   mixture is refitted to the second half of the chain (1, 3 or 6 components, chosen on
   held-out walkers) unless the chain since the last refit already mixes well (tau <= 4).
   Only the chain after the last refit, a time-homogeneous Markov chain, is judged and kept.

The measurements behind these choices, and the alternatives tried and not adopted, are in
docs/design/sampling.md. An independence sampler is only as good as its proposal's tails; DE
moves, refits and the R-hat gate over walkers guard against a walker stuck where the mixture
is too thin (tests/test_moves.py checks the move is exact from a mismatched proposal).

Convergence (see NOTES: walkers are not independent chains): after discarding a burn-in of
``burn_factor`` integrated autocorrelation times, the kept chain must be at least
``min_tau_multiple`` (50) times the largest autocorrelation time, the effective sample size
``nwalkers * n_kept / tau`` must reach ``ess_target`` for every coordinate, and the
rank-normalised R-hat over walkers, on exactly the draws returned, must be <= ``rhat_max``.
"""

import time
import warnings
from dataclasses import dataclass

import emcee
import numpy as np
from arviz_stats import rhat as az_rhat

from skinfit.inference.moves import DEMove, IndependenceMove, default_moves
from skinfit.inference.progress import Progress
from skinfit.inference.proposal import MixtureT, fit_mixture, select_mixture

__all__ = ["SamplerRun", "run_emcee", "initial_ball", "check_points", "independence_move", "adaptive_moves",
           "describe_moves", "importance_start", "sampler_settings"]

#: First step at which the independence proposal is refitted to the chain; later refits at
#: twice the previous step, for as long as the run has not converged.
ADAPT_FIRST = 50
#: No refit while the chain since the last one mixes this well (autocorrelation time, steps);
#: chosen with :data:`ADAPT_FIRST` by measurement (docs/design/sampling.md).
TAU_KEEP = 4.0
#: Importance sampling before the chain (:func:`importance_start`): draws per round, rounds,
#: the effective sample size below which the weights are too degenerate to refit to, and the
#: share of the draws above which the proposal is good enough.
IMPORTANCE_SIZE = 2000
IMPORTANCE_ROUNDS = 3
IMPORTANCE_MIN_ESS = 50
IMPORTANCE_GOOD = 0.5
#: Rounds at most, before the first with :data:`IMPORTANCE_MIN_ESS`, whose proposal is refitted
#: to tempered weights (:func:`importance_start`): each about doubles a too-narrow proposal's
#: width; a Laplace approximation at a cusp of the log density (wavy_surface: widths 20-100x too
#: small) took 5-9 (docs/design/sampling.md).
IMPORTANCE_TEMPERED = 12
#: Mixture sizes a refit chooses among (by held-out likelihood).
COMPONENT_CHOICES = (1, 3, 6)
#: Share of steps that are independence moves (the rest: differential evolution).
INDEPENDENCE_WEIGHT = 0.8
#: Independence updates per independence step, evaluated in one call
#: (:class:`~skinfit.inference.moves.IndependenceMove`); 3 was fastest of 1-4 (docs/design/sampling.md).
INDEPENDENCE_SUBSTEPS = 3
#: Steps between the first convergence checks of a fit (the interval grows to 10% of the
#: chain); the shipped posteriors converge after 100-300 steps (docs/design/sampling.md).
CHECK_EVERY = 50
#: Key of the sampler's evaluation count in a checkpoint's counts.
SAMPLER_EVALUATIONS = "sampler_evaluations"


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
    adaptation: tuple = ()  # refits of the independence proposal: dicts step, components


def initial_ball(post, z0, cov, nwalkers, rng, max_tries=20):
    """Walkers drawn from N(z0, cov); draws outside the support are redrawn, after five tries
    from shrinking balls around walkers placed so far (a MAP on a prior bound, where half of
    every ball around it lies outside, still gets its walkers)."""
    chol = np.linalg.cholesky(cov)
    out = np.empty((nwalkers, len(z0)))
    need = np.arange(nwalkers)
    scale, centre = 1.0, z0
    for attempt in range(max_tries):
        cand = centre + scale * rng.standard_normal((len(need), len(z0))) @ chol.T
        ok = np.isfinite(post(cand))
        out[need[ok]] = cand[ok]
        need = need[~ok]
        if len(need) == 0:
            return out
        if attempt >= 4:
            scale *= 0.5
            placed = np.setdiff1d(np.arange(nwalkers), need)
            if len(placed):
                centre = out[rng.choice(placed, len(need))]
    raise RuntimeError(f"could not place {len(need)} of {nwalkers} walkers inside the support around "
                       f"the MAP (outside the physical support: {post.counts['outside_support']} evaluations)")


def run_emcee(post, p0, rng, *, ess_target=400, rhat_max=1.01, min_tau_multiple=50,
              burn_factor=2.0, max_steps=20000, check_every=200, moves=None, progress=False,
              keep_total=4000, checkpoint=None, resume=None, proposal=None, natural=None):
    """Run emcee from walkers ``p0`` (nwalkers, d) until converged or ``max_steps``.

    With a ``proposal`` (a :class:`skinfit.inference.proposal.MixtureT` in sampling coordinates, e.g. the
    Laplace approximation), the moves are independence Metropolis-Hastings from it mixed with
    differential evolution (:func:`adaptive_moves`), and the proposal is refitted to the chain
    (:func:`_adapt`) at step :data:`ADAPT_FIRST`, then at twice the previous refit's step for as
    long as the run has not converged, unless it already mixes well (:func:`_apply_refit`).  Between
    refits the proposal is fixed: the chain from the last refit on is a time-homogeneous Markov
    chain, and only it is judged and kept.  Without a proposal,
    differential evolution and snooker moves alone (:func:`skinfit.inference.moves.default_moves`).

    Convergence is checked at step counts fixed by ``check_every`` and ``max_steps`` alone
    (:func:`check_points`), never by wall time, and emcee's RandomState is seeded by one draw
    from ``rng``: the chain is a pure function of (``p0``, ``proposal``, ``rng`` state,
    settings), and so is every refit.  ``checkpoint`` (a
    :class:`skinfit.inference.checkpoint.Checkpoint`) is written when due, at the end and on
    KeyboardInterrupt; ``resume`` (a :class:`skinfit.inference.checkpoint.Saved`) continues a
    checkpointed chain exactly where it stopped (its refits are recomputed from the saved
    chain).  ``natural`` maps sampling coordinates (k, d) to the parameters the user sees, on
    which R-hat is gated (ArviZ's R-hat includes a folded variant that is not invariant under
    the log and joint transforms of the sampling coordinates).
    """
    t0 = time.perf_counter()
    nwalkers, d = p0.shape
    seed = int(rng.integers(2**32 - 1))
    indep = independence_move(proposal) if proposal is not None else None
    if moves is None:
        moves = default_moves() if indep is None else adaptive_moves(indep)
    backend, spent, evaluated = emcee.backends.Backend(), 0.0, 0
    state = emcee.State(p0, random_state=np.random.RandomState(seed).get_state())
    if resume is not None and resume.iteration > 0:
        backend.reset(nwalkers, d)
        backend.grow(resume.iteration, None)
        backend.chain[:], backend.log_prob[:] = resume.chain, resume.log_prob
        backend.accepted[:] = resume.accepted
        backend.iteration, backend.random_state = resume.iteration, resume.random_state
        state = emcee.State(resume.chain[-1], log_prob=resume.log_prob[-1], random_state=resume.random_state)
        spent = resume.seconds
        saved = dict(resume.counts)
        # checkpoints written before the count was saved: one evaluation per walker and step
        evaluated = saved.pop(SAMPLER_EVALUATIONS, resume.iteration * nwalkers)
        if hasattr(post, "counts"):
            post.counts.update(saved)

    raised = []  # an error of the target (a forward function's ForwardError), raised after its step

    def log_prob(z):  # the target, counting its evaluations (moves make 1 to k a walker and step)
        nonlocal evaluated
        if raised:
            return np.full(len(z), -np.inf)
        evaluated += len(z)
        try:
            return post(z)
        except Exception as exc:  # emcee would print its traceback: kept, raised after the step
            raised.append(exc)
            return np.full(len(z), -np.inf)

    def tally():  # the evaluation counters, for the checkpoint
        return {**getattr(post, "counts", {}), SAMPLER_EVALUATIONS: evaluated}

    sampler = emcee.EnsembleSampler(nwalkers, d, log_prob, vectorize=True, moves=moves, backend=backend)
    n = backend.iteration
    history, start = [], 0  # refits so far; the chain is homogeneous from ``start`` on
    next_adapt = ADAPT_FIRST if indep is not None and max_steps > ADAPT_FIRST else None
    # resumed: replay the refits on the saved chain (one due at the saved step itself follows
    # that step's check, in the loop)
    while next_adapt is not None and next_adapt < n:
        start, next_adapt = _apply_refit(indep, backend.get_chain(), next_adapt, start, seed, proposal.nu,
                                         history, max_steps)
    counts = tally()  # as of the last completed step

    def save():
        if checkpoint is not None:
            checkpoint.write(chain=backend.get_chain(), log_prob=backend.get_log_prob(),
                             accepted=backend.accepted, random_state=backend.random_state or state.random_state,
                             counts=counts, seconds=spent + time.perf_counter() - t0)

    reasons, tau, burn, ess, rhat, thin = ("not run",), np.full(d, np.nan), 0, np.zeros(d), float("nan"), 1
    checks = list(check_points(check_every, max_steps))

    def following(step):  # the step of the next check (a refit step is one too), None past max_steps
        due = [c for c in checks if c >= step] + ([next_adapt] if next_adapt is not None and next_adapt >= step else [])
        return min(due) if due else None

    bar = Progress(ess_target) if progress else None
    if bar is not None:
        bar.start(n, following(n))
    try:
        while True:
            target = following(n)
            if target > n:
                for new_state in sampler.sample(state, iterations=target - n):
                    state = new_state  # the last one is where the next stretch starts
                    if raised:
                        raise raised[0]
                    counts = tally()
                    if bar is not None:
                        bar.step()
                    if checkpoint is not None and checkpoint.due():
                        save()
                n = target
            checks = [c for c in checks if c > target]
            # checked before any refit due now: a refit would discard a chain that has converged
            tau, burn, ess, rhat, thin, reasons = _check(
                sampler.get_chain(), ess_target, rhat_max, min_tau_multiple, burn_factor, keep_total,
                start=start, need_rhat=target >= max_steps or bar is not None, natural=natural)
            if not reasons:
                break
            if target == next_adapt:
                start, next_adapt = _apply_refit(indep, sampler.get_chain(), target, start, seed, proposal.nu,
                                                 history, max_steps)
            if bar is not None:  # against the next check, never against max_steps
                bar.check(n, tau, ess, rhat, reasons, following(n + 1) if checks else None)
            if not checks:
                break
        if bar is not None and not reasons:
            bar.check(n, tau, ess, rhat, reasons, None)
    except KeyboardInterrupt:
        save()
        raise
    finally:
        if bar is not None:
            bar.close()
    save()
    chain = sampler.get_chain()
    logp = sampler.get_log_prob()
    kept = chain[burn::thin].transpose(1, 0, 2)
    return SamplerRun(chain=kept, log_prob=logp[burn::thin].T, tau=tau, ess_emcee=ess, rhat_max=rhat,
                      acceptance=np.asarray(sampler.acceptance_fraction), n_steps=n, burn=burn,
                      thin=thin, converged=not reasons, reasons=tuple(reasons),
                      seconds=spent + time.perf_counter() - t0, evaluations=evaluated,
                      adaptation=tuple(history))


def sampler_settings():
    """The sampler's fixed settings (moves, refit schedule, importance start, check interval):
    part of what a campaign fit and a checkpoint belong to, so that neither is reused by a
    skinfit whose sampler differs (it would not give the same samples for the same seed)."""
    return {"moves": describe_moves(), "check_every": CHECK_EVERY, "adapt_first": ADAPT_FIRST, "tau_keep": TAU_KEEP,
            "components": list(COMPONENT_CHOICES), "importance": [IMPORTANCE_SIZE, IMPORTANCE_ROUNDS,
                                                                   IMPORTANCE_MIN_ESS, IMPORTANCE_GOOD,
                                                                   IMPORTANCE_TEMPERED]}


def describe_moves():
    """The moves of :func:`adaptive_moves`, in words (stored with every fit)."""
    return ("skinfit.inference.moves.IndependenceMove (mixture of Student-t, refitted; "
            f"{INDEPENDENCE_SUBSTEPS} updates "
            f"a step) {INDEPENDENCE_WEIGHT:g} + "
            f"skinfit.inference.moves.DEMove {1 - INDEPENDENCE_WEIGHT:g}")


def independence_move(proposal):
    """The independence move :func:`run_emcee` samples with, from ``proposal``."""
    return IndependenceMove(proposal, INDEPENDENCE_SUBSTEPS)


def adaptive_moves(indep):
    """Independence moves from the fitted proposal, mixed with differential evolution (which
    keeps local mixing where the proposal fits the posterior poorly)."""
    return [(indep, INDEPENDENCE_WEIGHT), (DEMove(), 1.0 - INDEPENDENCE_WEIGHT)]


def _apply_refit(indep, chain, step, start, seed, nu, history, max_steps):
    """At ``step``, refit ``indep``'s proposal (:func:`_adapt`) unless the chain since the last
    refit (``start``) already mixes well (largest autocorrelation time <= :data:`TAU_KEEP`,
    where another refit would only restart the count).  Records the
    decision in ``history``; returns (start of the homogeneous chain, step of the next refit or
    None past ``max_steps``)."""
    following = 2 * step if 2 * step < max_steps else None
    tau = integrated_time(chain[start + (step - start) // 4:step]).max()
    if tau <= TAU_KEEP:
        history.append({"step": step, "refit": False, "tau": float(tau)})
        return start, following
    indep.proposal = _adapt(chain[:step], seed, nu)
    history.append({"step": step, "refit": True, "components": len(indep.proposal.weights)})
    return step, following


def _adapt(chain, seed, nu, max_samples=2000):
    """The proposal refitted at step ``len(chain)``: a mixture fitted to the second half of the
    chain (at most ``max_samples`` of its points), with the number of components among
    :data:`COMPONENT_CHOICES` that predicts best (:func:`~skinfit.inference.proposal.select_mixture`:
    fitted on the even walkers, scored on the odd ones).  Its random draws (subsamples, EM
    seeds) come from (``seed``, step) alone: a resumed run refits identically.
    """
    step = len(chain)
    d = chain.shape[2]
    window = chain[step // 2:]
    rng = np.random.default_rng([seed, step])
    train = _subsample(window[:, 0::2].reshape(-1, d), max_samples // 2, rng)
    test = _subsample(window[:, 1::2].reshape(-1, d), max_samples // 2, rng)
    best = select_mixture(train, test, COMPONENT_CHOICES, rng, nu=nu)
    return fit_mixture(_subsample(window.reshape(-1, d), max_samples, rng), best, rng, nu=nu)


def importance_start(post, proposal, nwalkers, rng, *, size=IMPORTANCE_SIZE, rounds=IMPORTANCE_ROUNDS,
                     tempered=IMPORTANCE_TEMPERED):
    """Adapt the proposal by importance sampling before any MCMC step, and start the walkers
    from the weighted draws: population Monte Carlo (Cappe et al. 2004).

    Each round draws ``size`` points of the current proposal in one vectorised call of
    ``post`` and weights them by ``post / proposal``; the effective sample size of the weights
    measures how well that proposal matches the posterior.  While it is at least
    :data:`IMPORTANCE_MIN_ESS` and below :data:`IMPORTANCE_GOOD` of the draws, the proposal is
    refitted to the weighted draws (number of components chosen on held-out draws) for the
    next round, ``rounds`` such rounds at most.  Before the first round that reaches
    :data:`IMPORTANCE_MIN_ESS` (a Laplace approximation from a Hessian at a cusp, too narrow
    along some axes), up to ``tempered`` rounds refit the proposal's form (a Student-t and one
    twice as wide, as :func:`skinfit.results.fit.start` builds it) to the draws weighted by ``w**beta``,
    ``beta`` in [0, 1] the largest whose weights keep that effective sample size: the draws then
    represent ``post**beta * proposal**(1 - beta)``, between the two, wider than a too-narrow
    proposal where the posterior is.  The result is the best proposal measured, and ``nwalkers``
    distinct draws of its round picked with probability proportional to their weights (in the
    typical set: little burn-in).  Returns (proposal, walkers or None when every round's weights
    were degenerate, list of rounds: draws, effective sample size, points inside the support,
    whether a refit followed, and ``beta`` for a tempered refit).
    """
    record, best, informative = [], None, 0  # best: (ess, proposal, walkers)
    while True:
        x = proposal.draw(rng, size)
        log_w = post(x) - proposal.logpdf(x)
        finite = np.isfinite(log_w)
        if finite.sum() < nwalkers:
            record.append({"draws": size, "ess": 0.0, "inside_support": int(finite.sum()), "refit": False})
            break
        w = np.where(finite, np.exp(log_w - log_w[finite].max()), 0.0)
        w /= w.sum()
        ess = float(1.0 / np.sum(w * w))
        if best is None or ess > best[0]:
            best = (ess, proposal, x[rng.choice(size, nwalkers, replace=False, p=_floor(w, finite))])
        informative += ess >= IMPORTANCE_MIN_ESS
        entry = {"draws": size, "ess": ess, "inside_support": int(finite.sum())}
        if informative:  # the weights say where the posterior is: population Monte Carlo
            entry["refit"] = ess < IMPORTANCE_GOOD * size and ess >= IMPORTANCE_MIN_ESS and informative < rounds
        else:  # degenerate so far: widen the proposal towards the posterior
            entry["refit"] = len(record) < tempered
            entry["beta"], w_beta = _tempered(log_w, finite, IMPORTANCE_MIN_ESS) if entry["refit"] else (None, None)
        record.append(entry)
        if not entry["refit"]:
            break
        if informative:
            half = size // 2
            k = select_mixture(x[:half], x[half:], COMPONENT_CHOICES, rng, train_weights=w[:half] + 1e-300,
                               test_weights=w[half:] + 1e-300, nu=proposal.nu)
            proposal = fit_mixture(x, k, rng, weights=w, nu=proposal.nu)
        else:
            one = fit_mixture(x, 1, rng, weights=w_beta, nu=proposal.nu)
            proposal = MixtureT.with_wide_half(one.means[0], one.covs[0], proposal.nu)
    if best is None or best[0] < IMPORTANCE_MIN_ESS:
        return proposal if best is None else best[1], None, record
    return best[1], best[2], record


def _tempered(log_w, finite, target):
    """The largest ``beta`` in [0, 1] (to 1e-3) at which the weights ``exp(beta * log_w)`` of the
    ``finite`` draws have an effective sample size of at least ``target`` (bisection: the size
    falls as ``beta`` grows, from the number of finite draws at 0), and those weights (0 outside
    the support; not normalised)."""
    top = log_w[finite].max()
    centred = log_w[finite] - top
    lo, hi = 0.0, 1.0
    while hi - lo > 1e-3:
        mid = 0.5 * (lo + hi)
        w = np.exp(mid * centred)
        lo, hi = (mid, hi) if w.sum() ** 2 / (w @ w) >= target else (lo, mid)
    return lo, np.where(finite, np.exp(lo * (log_w - top)), 0.0)


def _floor(w, finite):
    """Probabilities ``w`` with every draw inside the support (``finite``) given at least a tiny
    share (weights far below the largest underflow to 0), so that as many distinct draws as
    there are finite ones can be picked."""
    p = np.where(finite, np.maximum(w, 1e-12), 0.0)
    return p / p.sum()


def _subsample(x, size, rng):
    return x if len(x) <= size else x[np.sort(rng.choice(len(x), size, replace=False))]


def check_points(check_every, max_steps):
    """Step counts at which convergence is checked: every ``check_every`` steps, the interval
    growing to a tenth of the chain length, the last at ``max_steps`` (electroadhesion: 14
    checks, 0.63 s of 5.8 s of sampling, profiled)."""
    n = 0
    while n < max_steps:
        n = min(n + check_every, max_steps)
        yield n
        check_every = max(check_every, int(0.1 * n))


def _check(chain, ess_target, rhat_max, min_tau_multiple, burn_factor, keep_total, start=0, need_rhat=False,
           natural=None):
    """Convergence gate on the chain so far, a pure function of it.  Only steps after
    ``start`` (the last refit of the proposal) count.  One autocorrelation estimate, on the
    last three quarters of them, sets both the burn-in (``burn_factor`` x tau after
    ``start``, at most half of what follows it) and the effective sample size of the kept
    steps.  R-hat (the costlier part) is computed only when the other criteria pass, or when
    ``need_rhat``, on exactly the draws the run returns (kept steps thinned to at most
    ``keep_total`` draws, mapped by ``natural``): the R-hat a user computes from the result is
    the one gated on.

    Returns (tau, burn, ess, rhat, thin, reasons).
    """
    n, nwalkers, d = chain.shape
    tau = integrated_time(chain[start + (n - start) // 4:])
    burn = start + min((n - start) // 2, int(np.ceil(min(burn_factor * tau.max(), n))))
    kept = chain[burn:]
    n_kept = kept.shape[0]
    thin = max(1, int(np.ceil(n_kept * nwalkers / keep_total)))
    ess = nwalkers * n_kept / tau
    reasons = []
    if n_kept < min_tau_multiple * tau.max():
        reasons.append(f"chain of {n_kept} kept steps < {min_tau_multiple} x tau = {min_tau_multiple * tau.max():.0f}")
    if ess.min() < ess_target:
        reasons.append(f"min ESS {ess.min():.0f} < {ess_target}")
    rhat = float("nan")
    if need_rhat or not reasons:
        draws = kept[::thin]
        if natural is not None:
            draws = natural(draws.reshape(-1, d)).reshape(draws.shape)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rhat = float(np.max(az_rhat(draws.transpose(1, 0, 2), chain_axis=0, draw_axis=1)))
        if not rhat <= rhat_max:
            reasons.append(f"max R-hat {rhat:.3f} > {rhat_max}")
    return tau, burn, ess, rhat, thin, reasons


def integrated_time(x, c=5):
    """Integrated autocorrelation time per coordinate of x (steps, walkers, d) [steps].

    emcee's estimator (``emcee.autocorr.integrated_time(x, c, tol=0)``: the walkers'
    autocovariances averaged, Sokal's window ``M >= c tau(M)``), with one batched real FFT
    per coordinate, and two differences.  Each walker is centred on the mean over all walkers,
    not on its own mean: for walkers sampling the same distribution the two agree (within 4%
    on AR(1) chains of 4000 steps, tests/test_sampling.py), while a walker stuck away from the
    others (an independence sampler rejecting for many steps) counts as a long correlation
    instead of a zero-variance walker, which makes emcee's estimate NaN.  And where no window
    satisfies Sokal's condition (a chain shorter than c tau), the estimate at the whole length
    is returned, a lower bound, where emcee's ``auto_window`` returns the window 0 (tau = 1).
    """
    n = x.shape[0]
    size = 2 * (1 << (n - 1).bit_length())  # emcee: 2 * next_pow_two(n)
    tau = np.empty(x.shape[2])
    for j in range(x.shape[2]):
        f = np.fft.rfft(x[:, :, j] - x[:, :, j].mean(), n=size, axis=0)
        acov = np.fft.irfft(f.real**2 + f.imag**2, n=size, axis=0)[:n].mean(axis=1)
        if not acov[0] > 0:  # every walker constant: nothing moved
            tau[j] = np.inf
            continue
        taus = 2.0 * np.cumsum(acov / acov[0]) - 1.0
        short = np.arange(n) < c * taus  # Sokal: the first M >= c tau(M) ...
        tau[j] = taus[n - 1] if short.all() else taus[np.argmin(short)]  # ... else the chain is too short
    return tau
