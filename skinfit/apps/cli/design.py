"""``skinfit design MODEL --candidates GRID``: which measurements next
(:func:`skinfit.analysis.design.design`)."""

from pathlib import Path

from skinfit.analysis.design import FILES, design
from skinfit.errors import InputError
from skinfit.io.models import load_model
from skinfit.io.outputs import check_outputs
from skinfit.plots.design import plot_eig
from skinfit.results.fit import load_fit

__all__ = ["run"]


def run(args):
    """``skinfit design MODEL --candidates FILE --n N [--from FIT] [--params A,B] [--discriminate M ...]
    [--sigma S] [--seed S] [--out DIR]``."""
    if args.n <= 0:
        raise InputError("--n", f"the number of measurements must be > 0 (got {args.n})")
    created = False
    if args.out:  # made (or refused: an earlier design there, unless --overwrite) before the work
        check_outputs(args.out, FILES, command="skinfit design", overwrite=args.overwrite)
        out = Path(args.out)
        if out.exists() and not out.is_dir():
            raise InputError("--out", f"{out} is a file, not a folder")
        created = not out.exists()
        try:
            out.mkdir(parents=True, exist_ok=True)
            probe = out / ".skinfit-write-test"
            probe.touch()
            probe.unlink()
        except OSError as exc:
            raise InputError("--out", f"cannot write into {out} ({exc.strerror or exc})") from None
    try:
        return _design(args)
    except BaseException:
        if created and not any(Path(args.out).iterdir()):  # nothing written: leave no empty folder behind
            Path(args.out).rmdir()
        raise


def _design(args):
    params = [p.strip() for p in args.params.split(",")] if args.params else None
    if args.from_fit:
        source = load_fit(args.from_fit)
        if source.model_id != load_model(args.model).id:
            raise InputError("--from", f"fit {args.from_fit} is of model {source.model_id!r}, not {args.model!r}")
    else:
        source = args.model
    result = design(source, args.candidates, n=args.n, params=params, rng=args.seed,
                    discriminate=args.discriminate or (), baseline=args.baseline, noise_scale=args.sigma,
                    n_outer=args.outer, n_inner=args.inner)
    print(result.text())
    if args.out:
        out = result.write(args.out, overwrite=args.overwrite)
        plot_eig(result, out / "eig.png")
        print(f"\nwritten: {out / 'plan.csv'} (user units), candidates.csv, comparison.csv, sd.csv, eig.png")
    return 0
