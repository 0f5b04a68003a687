"""The ``skinfit`` command line: a thin layer over the library.

This package holds the parser and the dispatch; each command is a module of it (``fit``,
``compare``, ``design``, ...) with a ``run(args)`` that calls the library and prints.  A
command's module is imported only when that command runs, so that ``skinfit --help`` and
``skinfit models`` start without numpy, pandas or ArviZ (tests/test_startup.py).
"""

import argparse
import contextlib
import importlib
import os
import sys
import warnings
from pathlib import Path

from skinfit import __version__
from skinfit.apps.cli.listing import NothingFound
from skinfit.errors import InputError, MissingDependency
from skinfit.io.arguments import check_output_folder
from skinfit.io.paths import check_search_path, explicit_search_path, set_search_path

__all__ = ["main", "build_parser", "one_line"]


def _int_in(lo, hi, what):
    """argparse type: an integer lo <= n <= hi (a one-line usage error otherwise)."""

    def parse(text):
        try:
            value = int(text, 0) if text.strip().lower().startswith(("0x", "0o", "0b")) else int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what} (got {text!r})") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"expected {what} (got {text})")
        return value

    return parse


def _positive_float(text):
    """argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number > 0 (got {text!r})") from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0 (got {text})")
    return value


def _ci(text):
    """argparse type of ``--ci``: an interval probability 0 < p < 1 (e.g. 0.9)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an interval probability, e.g. 0.9 (got {text!r})") from None
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"expected an interval probability between 0 and 1, e.g. 0.9 (got {text})")
    return value


_CI_HELP = "probability of every interval shown (highest-density intervals; default 0.94)"

#: --seed: numpy seeds are >= 0, and a fit records its seed as a 64-bit integer
_SEED = _int_in(0, 2**63 - 1, "a seed, an integer 0 .. 2**63-1")
_COUNT = _int_in(1, 10**9, "a whole number >= 1")


def one_line(message):
    """``message`` as one printable line: characters that break a line (also for
    ``str.splitlines``: \\x1c-\\x1e, \\x85, \\u2028...) or are invisible (bidi controls) are
    written as their escapes, so an argument echoed in an error cannot split or disguise it."""
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in str(message))


def _comment(value):
    """argparse type of --comment: '#', '%', both, or 'none' (no comment lines)."""
    if value == "none":
        return ""
    if not value or not set(value) <= set("#%"):
        raise argparse.ArgumentTypeError(f"expected '#', '%', '#%' or 'none' (got {value!r})")
    return value


def _text(value):
    """argparse type of an argument without one: any text but a blank one (an empty ``--from ""``
    was taken for no ``--from``, an empty ``--out ""`` for the current folder)."""
    if not value.strip():
        raise argparse.ArgumentTypeError(f"expected a value (got {value!r})")
    return value


class _Parser(argparse.ArgumentParser):
    """The parser of skinfit and its commands: a value of every argument that takes one is
    checked (``_text`` where no type is given), and its error is one printable line."""

    def add_argument(self, *args, **kwargs):
        action = super().add_argument(*args, **kwargs)
        if action.type is None and action.nargs != 0 and action.choices is None:
            action.type = _text
        return action

    def error(self, message):
        super().error(one_line(message))


def _command(module, function="run"):
    """The function that runs a command: ``function`` of ``module``, imported when the command
    runs (the one import inside a function here: start-up, see the module's docstring)."""

    def run(args):
        return getattr(importlib.import_module(module), function)(args)

    return run


def build_parser():
    """The parser of ``skinfit`` and its commands (``skinfit --help``)."""
    p = _Parser(prog="skinfit", description="Bayesian inference for published "
                "skin-friction models: MAP (nlopt) + emcee, results as ArviZ trees.")
    p.add_argument("--version", action="version", version=f"skinfit {__version__}")
    p.add_argument("--path", action="append", metavar="DIR", default=[],
                   help="folder with models/, priors/, datasets/ searched first (repeatable); then "
                        "$SKINFIT_PATH, the user folder, the shipped files (see `skinfit models --verbose`)")
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("models", help="list the model cards (models/*.toml) with units and sources")
    s.add_argument("--json", action="store_true", help="machine-readable output")
    s.add_argument("--verbose", "-v", action="store_true", help="show the search path and where each card is from")
    s.add_argument("--strict", action="store_true", help="exit 1 when a card or plug-in cannot be read "
                                                         "(default: list the others, warn, exit 0)")
    s.set_defaults(func=_command("skinfit.apps.cli.models"))
    s = sub.add_parser("priors", help="show a model's priors with their literature sources "
                                      "(no MODEL: list prior files)")
    s.add_argument("model", nargs="?", help="model id or path of a prior file")
    s.add_argument("--json", action="store_true")
    s.add_argument("--verbose", "-v", action="store_true", help="show the search path and where each file is from")
    s.set_defaults(func=_command("skinfit.apps.cli.priors"))
    s = sub.add_parser("datasets", help="list the datasets on the search path (datasets/*/dataset.toml)")
    s.add_argument("--json", action="store_true")
    s.add_argument("--verbose", "-v", action="store_true", help="show the search path and where each dataset is from")
    s.set_defaults(func=_command("skinfit.apps.cli.datasets"))
    s = sub.add_parser("dataset", help="write a dataset card for a lab's file: skinfit dataset init FILE --model M")
    d = s.add_subparsers(dest="action", required=True)
    s = d.add_parser("init", help="map a lab table's headers (CSV, .xlsx, .mat, .h5) to a model's names and write "
                                  "a dataset folder that `skinfit fit MODEL DIR` reads, the file unchanged")
    s.add_argument("file", help="the table as the lab's software exported it")
    s.add_argument("--model", required=True, help="model id or path: its covariates and observables are mapped")
    s.add_argument("--out", required=True, help="dataset folder written: dataset.toml and a copy of FILE")
    s.add_argument("--column", action="append", metavar="HEADER=NAME[:UNIT]",
                   help='map a header to a skinfit name, with its unit if the header has none (repeatable), '
                        'e.g. --column "Ft=tangential_force:mN"')
    s.add_argument("--sep", choices=[",", ";", "tab"], help="CSV separator (default: detected)")
    s.add_argument("--decimal", choices=[".", ","], help="CSV decimal mark (default: detected)")
    s.add_argument("--comment", type=_comment, help="characters starting a comment line, '#', '%%', '#%%' or "
                   "'none' (default: detected)")
    s.add_argument("--encoding", choices=["utf-8", "utf-8-sig", "latin-1", "cp1252"],
                   help="CSV encoding (default: detected)")
    s.add_argument("--sheet", help="Excel sheet (default: the one sheet with data)")
    s.add_argument("--variable", help="MATLAB struct or HDF5 group holding the table, '/' for the top level "
                                      "(default: the one there is)")
    s.add_argument("--id", help="dataset id (default: from the file name)")
    s.add_argument("--kind", choices=["measured", "digitised"], default="measured",
                   help="provenance of the data (default measured)")
    s.add_argument("--overwrite", action="store_true", help="replace a card already in --out")
    s.add_argument("--json", action="store_true", help="print the mapping as JSON")
    s.set_defaults(func=_command("skinfit.apps.cli.dataset"))
    s = sub.add_parser("ingest", help="raw recordings (.mat, .h5, .csv) + a rig file -> a dataset, one row per "
                                      "stroke with standard errors (docs/from-your-rig.md)")
    s.add_argument("raw", nargs="+", help="raw recording files (one trial each, or an HDF5 file of trials)")
    s.add_argument("--rig", required=True, help="the rig file (TOML): channels, gains, filters, strokes")
    s.add_argument("--out", required=True, help="dataset folder to write (data.csv, dataset.toml, trials.csv)")
    s.add_argument("--review", action="store_true", help="also write OUT/review/index.html: each trial's traces, "
                   "the strokes found and kept, the rejected ones with the reason (written even when every trial is "
                   "rejected: then no dataset, exit status 2)")
    s.add_argument("--overwrite", action="store_true", help="replace a dataset already in --out")
    s.add_argument("--json", action="store_true", help="print the outcome as JSON")
    s.set_defaults(func=_command("skinfit.apps.cli.ingest"))
    s = sub.add_parser("fit", help="fit a model to a dataset: MAP, emcee, summary, result file")
    s.add_argument("model", help="model id (models/<id>.toml) or path")
    s.add_argument("dataset", help="dataset id (datasets/<id>/), its folder or card, or a CSV file with units "
                   "in its header (normal_force [mN], voltage [V], ...): its card is then written to OUT/dataset/")
    s.add_argument("--out", required=True, help="run directory; fit.nc and summary.csv go there")
    s.add_argument("--priors", help="prior file id or path (default: priors/<model>.toml)")
    s.add_argument("--seed", type=_SEED, default=None, help="seed: the same seed gives identical samples")
    s.add_argument("--split", action="append", metavar="PARAM=COLUMN",
                   help="fit PARAM once per level of COLUMN (repeatable), e.g. alpha=voltage")
    s.add_argument("--noise", choices=["normal", "student_t", "lognormal"], help="noise model override")
    s.add_argument("--ess", type=_positive_float, default=400, help="minimum effective sample size (default 400)")
    s.add_argument("--max-steps", type=_COUNT, default=20000, help="emcee step cap (default 20000)")
    s.add_argument("--by", action="append", metavar="COLUMN",
                   help="fit each level of COLUMN separately (repeatable, e.g. --by subject); "
                        "one result per group under --out plus index.json")
    s.add_argument("--resume", action="store_true",
                   help="continue an interrupted fit from its checkpoint in --out")
    s.add_argument("--overwrite", action="store_true",
                   help="replace the results already in --out (without it, an --out holding results is refused)")
    s.add_argument("--checkpoint-every", type=_positive_float, default=30.0, metavar="SECONDS",
                   help="seconds between checkpoints (OUT/checkpoint.h5) while sampling (default 30)")
    s.add_argument("--strict", action="store_true", help="exit non-zero if not converged or warned")
    s.add_argument("--quiet", action="store_true",
                   help="no progress (else a bar up to the next convergence check on a terminal, a line per check "
                        "in a log)")
    s.add_argument("--json", action="store_true", help="print the result as JSON (summary, seed, warnings)")
    s.add_argument("--ci", type=_ci, default=None, metavar="PROB", help=_CI_HELP)
    s.set_defaults(func=_command("skinfit.apps.cli.fit"))
    s = sub.add_parser("compare", help="rank fits of the same data by evidence (log Z, Bayes factors) and LOO")
    s.add_argument("runs", nargs="+", help="run directories or fit.nc files")
    s.add_argument("--method", default="bridge", choices=["bridge", "laplace", "nested"],
                   help="evidence estimator (default bridge sampling)")
    s.add_argument("--save-evidence", action="store_true",
                   help="store the evidence in each input fit file (rewrites them; default: inputs untouched)")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_command("skinfit.apps.cli.compare"))
    s = sub.add_parser("report", help="write a self-contained static HTML report of fits")
    s.add_argument("runs", nargs="+", help="run directories or fit.nc files, and folders written by "
                   "`skinfit design --out` "
                   "(a section each); a run's population saved by `skinfit population RUN` is shown when made from "
                   "the same fits (else one is computed with the defaults, and the report says so)")
    s.add_argument("--out", required=True, help="report directory, e.g. reports/NAME")
    s.add_argument("--json", action="store_true", help="print the report's path and fits as JSON")
    s.add_argument("--ci", type=_ci, default=None, metavar="PROB", help=_CI_HELP)
    s.set_defaults(func=_command("skinfit.report.html", "cli_report"))
    s = sub.add_parser("campaign", help="run a (models x datasets x groups) matrix of fits")
    s.add_argument("campaign", help="campaign TOML file")
    s.add_argument("--scheduler", help="Dask scheduler: tcp://HOST:PORT, or 'local' for a LocalCluster")
    s.add_argument("--workers", type=_COUNT, default=None, help="local worker processes (default: cores)")
    s.add_argument("--threads", type=_COUNT, default=None, help="BLAS/OpenMP threads per fit (default 1, "
                   "unless OMP_NUM_THREADS or the like is set)")
    s.add_argument("--json", action="store_true", help="print the index as JSON (progress goes to stderr)")
    s.set_defaults(func=_command("skinfit.apps.cli.campaign"))
    s = sub.add_parser("population", help="population distribution over per-subject fits (a --by run or a campaign)")
    s.add_argument("run", help="run directory of `skinfit fit --by` or a campaign out directory (index.json)")
    s.add_argument("--params", action="append", metavar="NAME[,NAME]", help="population parameters (default: "
                   "every model parameter; noise scales stay per subject)")
    s.add_argument("--family", action="append", metavar="PARAM=FAMILY",
                   help="normal, lognormal or student_t per parameter (default lognormal when positive)")
    s.add_argument("--correlated", action="store_true", help="correlated (multivariate normal) population")
    s.add_argument("--method", default="gibbs", choices=["gibbs", "reweight"], help="sampler (default gibbs)")
    s.add_argument("--model", help="the model to use from a campaign with several")
    s.add_argument("--seed", type=_SEED, default=None, help="seed: the same seed gives identical draws")
    s.add_argument("--max-sweeps", type=_COUNT, default=20000,
                   help="Gibbs sweeps at most before stopping unconverged (default 20000)")
    s.add_argument("--out", help="output directory (default RUN/population)")
    s.add_argument("--overwrite", action="store_true", help="replace a population already in --out")
    s.add_argument("--strict", action="store_true", help="exit 3 if not converged or the sampler warned")
    s.add_argument("--ci", type=_ci, default=None, metavar="PROB", help=_CI_HELP)
    s.set_defaults(func=_command("skinfit.apps.cli.population"))
    s = sub.add_parser("sbc", help="simulation-based calibration of a model (Talts et al. 2018)")
    s.add_argument("model", help="model id")
    s.add_argument("--dataset", help="shipped dataset whose design is simulated on (default: the model's)")
    s.add_argument("--n-sims", type=_COUNT, default=100, help="number of simulated datasets (default 100)")
    s.add_argument("--draws", type=_COUNT, default=99, help="posterior draws each truth is ranked among (default 99)")
    s.add_argument("--rows", type=_COUNT, help="use at most this many rows of the design, evenly spaced")
    s.add_argument("--ess", type=_positive_float, default=100, help="minimum ESS of each fit (default 100)")
    s.add_argument("--max-steps", type=_COUNT, default=4000, help="emcee step cap of each fit (default 4000)")
    s.add_argument("--jobs", type=_COUNT, default=1, help="simulations in parallel processes (default 1)")
    s.add_argument("--seed", type=_SEED, default=0)
    s.add_argument("--out", default=None, help="directory for the rank table and histogram")
    s.add_argument("--overwrite", action="store_true", help="replace the SBC results already in --out")
    s.set_defaults(func=_command("skinfit.apps.cli.sbc"))
    s = sub.add_parser("demo", help="fit every shipped dataset with its model and variants, compare, report")
    s.add_argument("--out", default="runs/demo", help="where the fits go (default runs/demo)")
    s.add_argument("--report", help="report directory (default OUT/report)")
    s.add_argument("--seed", type=_SEED, default=1, help="demo seed; each fit's seed derives from it")
    s.add_argument("--jobs", type=_COUNT, help="parallel fits (default: one per core)")
    s.add_argument("--dataset", action="append", help="only this shipped dataset (repeatable)")
    s.set_defaults(func=_command("skinfit.apps.cli.demo"))
    s = sub.add_parser("design", help="which measurements next: rank candidate conditions by expected "
                                      "information gain and propose a plan")
    s.add_argument("model", help="model id (models/<id>.toml)")
    s.add_argument("--candidates", required=True, help="TOML grid or list of candidate conditions, user units")
    s.add_argument("--n", type=int, default=24, help="measurements in the plan (default 24; checked by skinfit.design)")
    s.add_argument("--from", dest="from_fit", help="a saved fit (fit.nc or run directory): start from its posterior")
    s.add_argument("--params", help="target parameters, comma-separated (default all)")
    s.add_argument("--discriminate", nargs="+", metavar="MODEL", help="competing models: plan to tell them apart")
    s.add_argument("--baseline", help="dataset whose design is the baseline (default: the fit's or the model's)")
    s.add_argument("--sigma", type=float, help="noise sd (default: the fit's posterior median or the prior median)")
    s.add_argument("--outer", type=_COUNT, default=400, help="outer Monte Carlo draws (default 400)")
    s.add_argument("--inner", type=_COUNT, default=400, help="inner Monte Carlo draws (default 400)")
    s.add_argument("--seed", type=_SEED, default=0, help="seed of every Monte Carlo draw (recorded; default 0)")
    s.add_argument("--out", help="directory for plan.csv, candidates.csv, comparison.csv, sd.csv, eig.png")
    s.add_argument("--overwrite", action="store_true", help="replace the design already in --out")
    s.set_defaults(func=_command("skinfit.apps.cli.design"))
    return p


def _format_warning(message, category, filename, lineno, line=None):
    """One line per warning: its category and message, without the echoed source line."""
    return f"skinfit: {category.__name__}: {message}\n"


def _os_error_text(exc):
    """One line for an OSError at the boundary: what failed, where, and that nothing was replaced."""
    where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
    return (f"{where}{exc.strerror or exc} (errno {exc.errno}); files written before are unchanged"
            if exc.errno else f"{where}{exc}")


def main(argv=None):
    """Run ``skinfit ARGV`` (default: the process's arguments); returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    before = explicit_search_path()  # main() may run inside a process (a notebook, a test): put it back after
    set_search_path(args.path)
    try:
        return _main(args)
    finally:
        set_search_path(before)


def _main(args):
    out = Path(args.out).absolute() if isinstance(getattr(args, "out", None), str) else None
    while out is not None and not out.parent.exists():  # the topmost folder the command may create
        out = out.parent
    fresh = out is not None and not out.exists()
    shown = warnings.formatwarning
    with warnings.catch_warnings():
        warnings.simplefilter("default")  # each distinct warning once
        warnings.formatwarning = _format_warning
        try:
            code = _run(args)
        finally:
            warnings.formatwarning = shown
    if fresh and code not in (0, 3):  # refused or failed: leave no empty output folder behind
        _remove_empty(out)
    return code


def _remove_empty(folder):
    """Remove ``folder`` and its sub-folders if they hold no files."""
    if not folder.is_dir():
        return
    subs = [p for p in folder.rglob("*") if p.is_dir() and not p.is_symlink()]
    for sub in sorted(subs, key=lambda p: len(p.parts), reverse=True) + [folder]:
        with contextlib.suppress(OSError):
            sub.rmdir()  # only an empty folder goes: a file written meanwhile keeps its folder


def _run(args):
    try:
        check_search_path()  # a mistyped --path or $SKINFIT_PATH folder: refused, not skipped
        for option in ("out", "report"):  # every such option names a folder: refused now, not after the work
            if getattr(args, option, None) is not None:
                noun = "report" if "report" in (option, args.command) else "results"
                check_output_folder(getattr(args, option), f"--{option}", None,
                                    f"--{option} names the folder the {noun} {'is' if noun == 'report' else 'are'} "
                                    "written into")
        code = args.func(args)
        sys.stdout.flush()  # a closed pipe shows here, inside the handler below
    except InputError as exc:
        print(f"skinfit: error: {one_line(exc)}", file=sys.stderr)
        return 2
    except NothingFound as exc:
        print(exc, file=sys.stderr)
        return 1
    except MissingDependency as exc:
        print(f"skinfit: error: {one_line(exc)}", file=sys.stderr)
        return 2
    except RuntimeError as exc:  # MAPError: no start possible, its message names the rows (skinfit.inference.optimize)
        optimize = sys.modules.get("skinfit.inference.optimize")  # not imported at start-up: raised only once it is
        if optimize is None or not isinstance(exc, optimize.MAPError):
            raise
        print(f"skinfit: error: {one_line(exc)}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. `skinfit models | head`: the reader left; no traceback
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except OSError as exc:  # a disk full or read-only: the result files as they were before
        print(f"skinfit: error: {_os_error_text(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("skinfit: interrupted", file=sys.stderr)
        return 130
    return code or 0
