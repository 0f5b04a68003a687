"""``skinfit demo``: every shipped dataset fitted, compared and reported (:mod:`skinfit.apps.demo`)."""

import sys
from pathlib import Path

from skinfit.apps.demo import run_demo

__all__ = ["run"]


def run(args):
    run_demo(args.out, args.report or str(Path(args.out) / "report"), seed=args.seed, jobs=args.jobs,
             datasets=args.dataset)
    sys.stdout.flush()
    return 0
