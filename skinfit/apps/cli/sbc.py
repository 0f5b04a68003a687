"""``skinfit sbc MODEL``: simulation-based calibration of a model (:mod:`skinfit.analysis.sbc`)."""

from skinfit.analysis.sbc import FILES, markdown_table, run_sbc, write_sbc
from skinfit.io.outputs import check_outputs
from skinfit.plots.sbc import plot_ranks

__all__ = ["run"]


def run(args):
    """``skinfit sbc MODEL [--dataset D] [--n-sims N] [--draws L] [--rows N] [--seed S] [--jobs J]
    [--out DIR]``."""
    if args.out:  # an earlier run there: refused before the simulations, unless --overwrite
        check_outputs(args.out, FILES, command="skinfit sbc", overwrite=args.overwrite)
    result = run_sbc(args.model, args.dataset, n_sims=args.n_sims, seed=args.seed, n_draws=args.draws,
                     n_rows=args.rows, ess_target=args.ess, max_steps=args.max_steps, jobs=args.jobs,
                     progress=print)
    print(markdown_table(result))
    print(f"\n{len(result.ranks)} simulations; {'all parameters pass' if result.passed else 'NOT calibrated'} "
          f"at the {result.settings['alpha']:.0%} level")
    if args.out:
        out = write_sbc(result, args.out, overwrite=args.overwrite)
        plot_ranks(result, out / "ranks.png")
        print(f"written: {out}")
    return 0 if result.passed else 1
