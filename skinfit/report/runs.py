"""What ``skinfit report`` reads: the fits of run folders and campaigns, the populations saved
beside them, and the model comparisons among the fits.
"""

import sys
from pathlib import Path

from skinfit.analysis.compare import compare
from skinfit.analysis.groups import read_index
from skinfit.analysis.population.result import load_population
from skinfit.errors import InputError

__all__ = ["collect_runs", "indexed_fits", "saved_populations", "comparison_tables", "model_setup"]


def collect_runs(paths):
    """Run directories or fit.nc files. A directory with an index.json (a ``skinfit fit --by``
    run, a campaign) gives the fits its index lists as done, and names on stderr any fit.nc
    below it that the index does not list (another run's, not reported); another directory
    gives every fit.nc below it."""
    out = []
    for p in map(Path, paths):
        if p.is_file() or (p / "fit.nc").exists():
            out.append(p)
        elif (p / "index.json").is_file():
            listed = indexed_fits(p / "index.json")
            known = {f.resolve() for f in listed}
            extra = [f for f in sorted(p.glob("**/fit.nc")) if f.resolve() not in known]
            if extra:
                print(f"skinfit report: warning: {len(extra)} fit file(s) below {p} are not in its index.json "
                      f"(e.g. {extra[0]}): not reported (name them to report them)", file=sys.stderr)
            out += listed
        elif p.is_dir():
            found = sorted(p.glob("**/fit.nc"))
            if not found:
                raise InputError(p, "no fit.nc in this directory or below it (run `skinfit fit ... --out` first)")
            out += found
        else:
            raise InputError(p, "no such run directory or fit file")
    return out


def indexed_fits(index):
    """The fit files an index.json lists (:func:`skinfit.analysis.groups.read_index`), naming on stderr
    a campaign's fits that are not complete."""
    rows, skipped = read_index(index)
    if skipped:
        print(f"skinfit report: {skipped} fit(s) of {index} not complete (failed or pending): not reported",
              file=sys.stderr)
    if not rows:
        raise InputError(index, "lists no completed fit")
    return [r["path"] for r in rows]


def saved_populations(paths):
    """The populations ``skinfit population RUN`` saved beside the runs given (RUN/population/
    population.nc), read; one that cannot be read is named on stderr and left out."""
    out = []
    for p in dict.fromkeys(Path(p) / "population" / "population.nc" for p in paths):
        if p.is_file():
            try:
                out.append(load_population(p))
            except Exception as exc:  # a damaged file is reported; the report computes its own
                print(f"skinfit report: warning: {p} could not be read ({type(exc).__name__}: {exc}): not used",
                      file=sys.stderr)
    return out


def comparison_tables(fits, echo=None):
    """Evidence/LOO tables for fits of different models (or one model under other priors, split,
    noise or constants) on the same data (:func:`skinfit.compare`), one per dataset content
    (sha256): two versions of a dataset are two tables, named by the data's sha256 where they
    share a name. A comparison that fails is said through ``echo`` (default: on stderr)."""
    echo = echo or (lambda message: print(message, file=sys.stderr))
    groups = {}
    for key, f in fits:
        groups.setdefault(f.attrs["dataset_sha256"], []).append((key, f))
    groups = {sha: group for sha, group in groups.items() if len({model_setup(f) for _, f in group}) > 1}
    if not groups:
        return None
    tables = {}
    named = [group[0][1].dataset_id for group in groups.values()]
    for (sha, group), name in zip(groups.items(), named):
        name = name if named.count(name) == 1 else f"{name} (data {sha[:12]})"
        try:
            tables[name] = compare([f for _, f in group])
        except (ValueError, RuntimeError) as exc:  # the report still shows every fit
            echo(f"skinfit report: comparison on {name} failed: {exc}")
    if not tables:
        return None
    return next(iter(tables.values())) if len(tables) == 1 else tables


def model_setup(fit):
    """What makes a fit another model of its data: the model card and prior file, the split,
    noise and constants (not the seed, walkers or file: runs of one model)."""
    return fit.model_id, fit.attrs.get("priors_sha256"), fit.attrs.get("model_sha256"), fit.attrs.get("setup")
