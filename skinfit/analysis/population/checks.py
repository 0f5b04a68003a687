"""What :func:`skinfit.analysis.population.population.population` checks before it samples, and what it says when
its hyper-posterior did not converge.

* :func:`check_arguments`: every argument, one line naming it and what was expected, before
  any fit is read or any draw made.
* :func:`check_subjects`: the fits are distinct subjects (no fit counted twice, no two fits of
  one group of one data file under two labels) of the data as they are now (a data file
  edited since the fits were made is refused: the fits are stale).
* :func:`undetermined` and :func:`not_converged`: on a hyper-posterior that did not converge,
  which population parameters the data cannot determine and why (every subject's own fit
  barely moves its prior, so their population mean and sd follow the hyper-priors alone), and
  the options that would help (``--params`` without them, ``--max-sweeps`` with an estimate
  from the rate the effective sample size grew).
"""

from __future__ import annotations

import json
import math
import numbers
import os
from pathlib import Path

import numpy as np
from scipy import stats

from skinfit.analysis.groups import data_drift
from skinfit.errors import InputError

__all__ = ["check_arguments", "check_prob", "check_size", "check_subjects", "undetermined", "not_converged", "FAMILIES",
           "MAX_DRAW_BYTES"]

FAMILIES = ("normal", "lognormal", "student_t")
#: the largest set of draws a population may hold while sampling (chains x 2000 kept sweeps x
#: subjects' vectors), refused above with the estimate
MAX_DRAW_BYTES = 4 * 2**30


def _int(value, name, lo, hi=None):
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise InputError("population", f"expected a whole number (got {value!r})", field=name)
    if value < lo or (hi is not None and value > hi):
        span = f">= {lo}" if hi is None else f"in {lo} .. {hi}"
        raise InputError("population", f"expected a whole number {span} (got {value})", field=name)
    return int(value)


def _number(value, name, lo, *, above=False, hi=None):
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise InputError("population", f"expected a finite number (got {value!r})", field=name)
    if (value <= lo if above else value < lo) or (hi is not None and value > hi):
        span = f"{'>' if above else '>='} {lo:g}" + ("" if hi is None else f" and <= {hi:g}")
        raise InputError("population", f"expected a number {span} (got {value:g})", field=name)
    return float(value)


def check_prob(prob, where):
    """Refuse an interval probability outside (0, 1) (an InputError naming ``where``)."""
    if isinstance(prob, bool) or not isinstance(prob, numbers.Real) or not 0 < prob < 1:
        raise InputError(where, f"expected an interval probability between 0 and 1 (got {prob!r})", field="prob")
    return float(prob)


def check_arguments(parameters, family, correlated, method, rng, model, chains, ess_target, rhat_max, max_sweeps,
                    burn, min_contraction, n_draws, max_steps, cache):
    """Refuse a bad argument of :func:`skinfit.analysis.population.population.population` with a one-line
    InputError naming it; returns ``(parameters, family)`` as lists / dicts (``parameters``
    None stays None: every model parameter)."""
    if parameters is not None:
        items = [parameters] if isinstance(parameters, str) else parameters
        try:
            items = list(items)
        except TypeError:
            raise InputError("population", f"expected a parameter name or a list of them (got {parameters!r})",
                             field="parameters") from None
        bad = [p for p in items if not isinstance(p, str) or not p.strip()]
        if bad or not items:
            raise InputError("population", "expected at least one parameter name" if not items else
                             f"expected parameter names (got {bad[0]!r})", field="parameters")
        twice = sorted({p for p in items if items.count(p) > 1})
        if twice:
            raise InputError("population", f"{', '.join(twice)} named twice: each population parameter once",
                             field="parameters")
        parameters = items
    if family is not None and not isinstance(family, str):
        try:
            family = dict(family)
        except (TypeError, ValueError):
            raise InputError("--family", f"expected a family or a mapping parameter -> family (got {family!r})") \
                from None
    for key, fam in ({"every parameter": family} if isinstance(family, str) else family or {}).items():
        if not isinstance(key, str) or not key:
            raise InputError("--family", f"expected a parameter name (got {key!r})")
        if fam not in FAMILIES:
            raise InputError("--family", f"{key}: unknown family {fam!r} (expected one of {', '.join(FAMILIES)})")
    if not isinstance(correlated, (bool, np.bool_)):
        raise InputError("population", f"expected True or False (got {correlated!r})", field="correlated")
    if method not in ("gibbs", "reweight"):
        raise InputError("population", f"unknown method {method!r} (expected gibbs or reweight)", field="method")
    if not (rng is None or isinstance(rng, np.random.Generator)) and (
            isinstance(rng, bool) or not isinstance(rng, numbers.Integral) or rng < 0):
        raise InputError("population", f"expected a seed (an integer >= 0), None or a numpy Generator "
                         f"(got {rng!r})", field="rng")
    if model is not None and (not isinstance(model, str) or not model):
        raise InputError("population", f"expected a model id (got {model!r})", field="model")
    _int(chains, "chains", 2, 1000)
    _number(ess_target, "ess_target", 0, above=True, hi=1e7)
    _number(rhat_max, "rhat_max", 1, above=True)
    _int(burn, "burn", 0)
    _int(max_sweeps, "max_sweeps", burn + 1)
    _number(min_contraction, "min_contraction", 0, hi=1)
    _int(n_draws, "n_draws", 10)
    _int(max_steps, "max_steps", 1)
    if cache is not None:
        if not isinstance(cache, (str, os.PathLike)):
            raise InputError("population", f"expected a file path (got {cache!r})", field="cache")
        if Path(cache).is_dir():
            raise InputError(cache, "is a folder: expected the path of the population cache file", field="cache")
    return parameters, family


def check_size(chains, n_subjects, dim, p):
    """Refuse, with the estimate, a Gibbs run whose draws would not fit in memory."""
    need = 8 * chains * 2000 * (n_subjects * dim + p * p + p)
    if need > MAX_DRAW_BYTES:
        raise InputError("population", f"{chains} chains of {n_subjects} subjects x {dim} sampled parameters would "
                         f"hold ~{need / 2**30:.1f} GiB of draws (limit {MAX_DRAW_BYTES / 2**30:.0f} GiB): use fewer "
                         "chains", field="chains")


def check_subjects(fits, digests):
    """Refuse fits that are not distinct subjects of the data as they are now.

    ``fits``: {label: Fit or DrawsFit}; ``digests``: {label: :func:`subject_digest`} of the
    Fits (absent for draws).  Two labels holding the same fit, or the fits of one group of
    one data file, count one subject twice; a fit whose data file has changed since
    (:func:`skinfit.analysis.groups.data_drift`) is of other data than the file now holds.
    """
    seen = {}
    for label, digest in digests.items():
        if digest in seen:
            raise InputError(f"subject {label}", f"holds the same fit as subject {seen[digest]} (identical draws of "
                             "the same data): one subject would count twice; check which fit each label reads")
        seen[digest] = label
    sources = {}
    for label, f in fits.items():
        attrs = getattr(f, "attrs", {})
        if "source" not in attrs or "group" not in attrs:
            continue
        try:
            key = (json.loads(attrs["source"])["sha256"], attrs["group"])
        except (ValueError, KeyError, TypeError):
            continue
        if key in sources:
            raise InputError(f"subject {label}", f"is a fit of group {attrs['group']!r} of the same data as subject "
                             f"{sources[key]}: one subject would count twice; check which fit each label reads")
        sources[key] = label
    stale = data_drift([(label, f) for label, f in fits.items() if digests.get(label) is not None])
    if stale:
        names = [m.split(":", 1)[0] for m in stale]
        shown = ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")
        raise InputError(f"subject {names[0]}", f"{stale[0].split(': ', 1)[1]}; the fits of {shown} are stale: fit "
                         "them again (skinfit fit ... --by) before their population")


def _hyper_prior_log_sd_interval(scale, nu=2.0):
    """90% central interval of a half-t(nu, scale) sd (the hyper-prior of a population sd)."""
    return tuple(float(scale * stats.t.ppf(0.5 + q / 2, nu)) for q in (0.05, 0.95))


def undetermined(result, min_contraction):
    """The population parameters the data cannot determine: those whose every subject's own
    fit barely moves its prior (contraction < ``min_contraction``), in order, with their
    contraction range and the 90% interval of their population sd against its hyper-prior's.
    A list of ``(name, (lo, hi) contraction, (lo, hi) sd posterior, (lo, hi) sd hyper-prior)``."""
    out = []
    for j, name in enumerate(result.parameters):
        c = [result.contraction.get(s, {}).get(name, np.nan) for s in result.subjects]
        if c and all(np.isfinite(c)) and max(c) < min_contraction:
            sd = result.sd[:, :, j].ravel()
            scale = _hyper_scale(result, name)
            prior = _hyper_prior_log_sd_interval(scale) if scale else (np.nan, np.nan)
            out.append((name, (min(c), max(c)), tuple(float(v) for v in np.quantile(sd, [0.05, 0.95])), prior))
    return out


def _hyper_scale(result, name):
    """The scale s of the half-t(2, s) hyper-prior of a parameter's population sd (recorded)."""
    text = result.hyperpriors.get(name, {}).get("sd", "")
    try:
        return float(text.split("scale=", 1)[1].rstrip(")"))
    except (IndexError, ValueError):
        return None


def not_converged(result, targets, min_contraction, seconds):
    """The one-line warning of a hyper-posterior that did not converge: the worst diagnostics,
    which hyper-parameters the data cannot determine and why, and what to rerun with.
    ``targets``: (rhat_max, ess_target); ``seconds``: the sampling time so far."""
    rhat_max, ess_target = targets
    diag = result.diagnostics()
    worst_r = diag.loc[diag["r_hat"].idxmax()] if diag["r_hat"].notna().any() else None
    ess = diag[["ess_bulk", "ess_tail"]].min(axis=1)
    worst_e = diag.loc[ess.idxmin()]
    what = {"mu": "mu", "sd": "tau", "corr": "corr"}
    text = (f"hyper-posterior not converged after {result.sampler.get('sweeps', result.sampler.get('n_steps', '?'))} "
            f"{'sweeps' if 'sweeps' in result.sampler else 'steps'}: max R-hat "
            + (f"{worst_r['r_hat']:.3f} ({what[worst_r['quantity']]} of {worst_r['parameter']})"
               if worst_r is not None else "n/a")
            + f", min ESS {ess.min():.0f} ({what[worst_e['quantity']]} of {worst_e['parameter']}) "
              f"(targets {rhat_max:g}, {ess_target:g}): its numbers are not to be reported as they stand")
    weak = undetermined(result, min_contraction)
    advice = []
    if weak:
        names = [w[0] for w in weak]
        one = len(names) == 1
        parts = [f"{n}: contraction {c[0]:.2f}-{c[1]:.2f}, tau 90% interval {sd[0]:.3g}-{sd[1]:.3g} against its "
                 f"hyper-prior's {pr[0]:.3g}-{pr[1]:.3g}" for n, c, sd, pr in weak]
        S = len(result.subjects)
        text += (f". The data cannot determine the population of {', '.join(names)}: each of the {S} subjects' own "
                 f"fits barely moves {'its' if one else 'their'} prior ({'; '.join(parts)}), so the population "
                 f"mean mu and sd tau of {'it' if one else 'them'} rest on the hyper-priors"
                 + (f" and on {S} subjects ({S - 1} degrees of freedom for a sd)" if S < 5 else "")
                 + ", and the sampler crosses them slowly")
        rest = [p for p in result.parameters if p not in names]
        if rest:
            advice.append(f"--params {','.join(rest)} (Python: parameters={rest!r}), with which {', '.join(names)} "
                          f"keep{'s' if one else ''} {'its' if one else 'their'} prior per subject")
    if "sweeps" in result.sampler:
        # the ESS grows about in proportion to the sweeps, R-hat - 1 shrinks about in inverse proportion
        sweeps = int(result.sampler["sweeps"])
        grown = max(float(ess.min()), 1.0)
        rhat = float(diag["r_hat"].max()) if diag["r_hat"].notna().any() else 1.0
        need = max(ess_target / grown if grown < ess_target else 1.0,
                   (rhat - 1) / (rhat_max - 1) if rhat > rhat_max else 1.0)
        need = _round_up(sweeps * (1.25 * need if need > 1 else 2.0))
        advice.append(f"--max-sweeps {need} (Python: max_sweeps={need}; from the rates the ESS and R-hat "
                      f"improved, about {seconds * need / max(sweeps, 1) / 60:.0f} min at this run's pace)")
    else:
        advice.append("--method gibbs (Python: method='gibbs')")
    return text + ". Rerun with " + ", or with ".join(advice)


def _round_up(n):
    """n rounded up to two significant digits."""
    n = max(math.ceil(n), 1)
    q = 10 ** max(len(str(n)) - 2, 0)
    return int(math.ceil(n / q) * q)
