"""``skinfit population RUN``: the population distribution over the per-subject fits of a
``skinfit fit --by`` run or a campaign (:func:`skinfit.analysis.population.population.population`)."""

import contextlib
import sys
import time
import warnings
from pathlib import Path

import pandas as pd

from skinfit.analysis.population.checks import FAMILIES
from skinfit.analysis.population.population import BURN, population, population_tables
from skinfit.analysis.population.result import PopulationWarning
from skinfit.errors import InputError
from skinfit.inference.checkpoint import CheckpointLock, replace_atomic
from skinfit.io.outputs import check_outputs
from skinfit.results.intervals import CI_PROB, interval_name
from skinfit.results.summary import format_numbers

__all__ = ["run", "FILES"]


def _parse_family(items):
    """``--family PARAM=FAMILY`` items -> {param: family}; each parameter once."""
    out = {}
    for item in items or []:
        name, sep, fam = item.partition("=")
        name, fam = name.strip(), fam.strip()
        if not sep or not fam or not name:
            raise InputError("--family", f"expected PARAMETER=FAMILY (got {item!r}; families: {', '.join(FAMILIES)})")
        if name in out:
            raise InputError("--family", f"{name} given twice ({name}={out[name]} and {item}): give each parameter "
                                         "once")
        out[name] = fam
    return out


#: The files ``skinfit population`` writes into its --out (besides its cache, .cache/).
FILES = ("population.nc", "population_summary.csv", "population_subjects.csv", "population_effects.csv")


def _parse_params(items):
    """``--params NAME[,NAME]`` items -> a list of names (None: every model parameter)."""
    if not items:
        return None
    names = []
    for item in items:
        parts = [p.strip() for p in item.split(",")]
        if not all(parts):
            raise InputError("--params", f"expected NAME[,NAME] (got {item!r}: an empty name)")
        names += parts
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError("--params", f"{', '.join(twice)} given twice: name each population parameter once")
    return names


def run(args):
    """``skinfit population RUN_DIR``: the population of a ``fit --by`` run or a campaign;
    writes ``population.nc`` (ArviZ tree) and ``population_summary.csv`` /
    ``population_subjects.csv`` / ``population_effects.csv`` to ``--out`` and prints them.

    Every option is checked before a fit is read; the run is read while no writer holds it
    and ``--out`` is held with the lock ``skinfit fit`` takes there (a second population into
    the same ``--out`` is refused, not interleaved); files are replaced atomically.  A result
    with problems (not converged, a sampler that rarely moved; :attr:`PopulationResult.problems`)
    is written and said so on stderr; with ``--strict`` the exit status is then 3."""
    t0 = time.perf_counter()
    params, family = _parse_params(args.params), _parse_family(args.family)
    if args.max_sweeps <= BURN:
        raise InputError("--max-sweeps", f"expected more than the {BURN} burn-in sweeps (got {args.max_sweeps})")
    run = Path(args.run)
    if not run.exists():
        raise InputError(run, "no such run folder (expected the --out of `skinfit fit ... --by` or of a campaign)")
    out = Path(args.out) if args.out else (run if run.is_dir() else run.parent) / "population"
    check_outputs(out, FILES, command="skinfit population", overwrite=args.overwrite)  # before the sampling
    if out.resolve() == (run if run.is_dir() else run.parent).resolve():
        raise InputError(out, "is the run's own folder: give the population another --out (default RUN/population)")
    made = [p for p in (out, *out.parents) if not p.exists()]  # removed again if the population fails
    try:
        with CheckpointLock(out / "checkpoint.h5"):  # the lock of `skinfit fit --out`: one writer at a time
            # again inside the lock: a second population into this --out may have finished meanwhile
            check_outputs(out, FILES, command="skinfit population", overwrite=args.overwrite)
            with warnings.catch_warnings():  # the warnings are printed below, with the result
                warnings.simplefilter("ignore", PopulationWarning)
                result = population(args.run, params, family=family, correlated=args.correlated,
                                    method=args.method, rng=args.seed, model=args.model,
                                    max_sweeps=args.max_sweeps, cache=out / ".cache" / "population.npz")
            tables = population_tables(result, **({} if getattr(args, "ci", None) is None else {"prob": args.ci}))
            for name, table in (("summary", "hyper"), ("subjects", "subjects"), ("effects", "effects")):
                replace_atomic(out / f"population_{name}.csv", tables[table].to_csv(index=False).encode())
            path = result.save(out / "population.nc")
    except BaseException:
        if made:  # a folder this command made holds at most its lock and an empty cache folder: nothing left
            (out / ".checkpoint.h5.lock").unlink(missing_ok=True)
            for folder in (out / ".cache", *made):
                # not empty (another writer's files) or already gone: left as it is
                with contextlib.suppress(OSError):
                    folder.rmdir()
        raise
    s = result.sampler
    lines = [f"population of {len(result.subjects)} subjects ({result.model_id}), method {s['method']}, "
             f"seed {s.get('seed')}",
             "families: " + ", ".join(f"{p} {f}" + ("" if (p in family) else " (default)")
                                      for p, f in zip(result.parameters, result.families)),
             "hyper-priors (from the prior file): " + "; ".join(f"{p}: mu ~ {h['mu']}, sd ~ {h['sd']}"
                                                               for p, h in result.hyperpriors.items()
                                                               if not p.startswith("_")),
             "converged: "
             f"{'yes' if result.converged and not any('not converged' in w for w in result.warnings) else 'NO'}"
             f"  (max R-hat {s['rhat_max']:.4f}, min ESS {s['ess_min']:.0f}"
             + (f", {s['sweeps']} sweeps of {s['chains']} chains" if "sweeps" in s else "") + ")",
             *[f"{'WARNING' if w in result.problems else 'NOTE'}: {w}" for w in result.warnings], ""]
    lines.append(f"intervals: {interval_name(CI_PROB if getattr(args, 'ci', None) is None else args.ci)} "
                 "(highest-density); numbers to the precision their posterior sd allows (the CSV files have every "
                 "digit)")
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        lines.append(format_numbers(tables["hyper"]).to_string(index=False))
        if len(tables["effects"]):
            lines += ["", "conditions as effects (population level):",
                      format_numbers(tables["effects"]).to_string(index=False)]
    print("\n".join(lines))
    print(f"\nwritten: {path}, {out / 'population_summary.csv'}, population_subjects.csv, population_effects.csv"
          f"  ({time.perf_counter() - t0:.1f} s)")
    if result.problems:
        sys.stdout.flush()
        verdict = "NOT converged" if not result.converged or any("not converged" in w for w in result.problems) \
            else "has problems"
        print(f"skinfit: the population {verdict} ({len(result.problems)} problem(s), see WARNING above): its "
              f"numbers are not to be reported as they stand" + ("" if args.strict else
                                                                 "; --strict makes this exit with status 3"),
              file=sys.stderr)
        if args.strict:
            return 3
    return 0
