"""``skinfit ingest RAW... --rig RIG.toml --out DIR [--review]``: raw recordings -> a per-stroke dataset.

With ``--review`` the page is written even when every trial is rejected; the command then exits
non-zero with one line naming the page (no dataset written)."""

import json
from pathlib import Path

from skinfit.errors import InputError
from skinfit.report.review import ingest_with_review

__all__ = ["run"]


def run(args):
    out = Path(args.out)
    if (out / "dataset.toml").exists() and not args.overwrite:
        raise InputError(args.out, "holds a dataset already (pass --overwrite to replace it)", field="--out")
    ing, review = ingest_with_review(args.raw, args.rig, out, review=args.review)
    kept = [t for t in ing.trials if t.kept]
    if args.json:
        print(json.dumps({"dataset": str(out), "rows": len(ing.dataset), "review": str(review) if review else None,
                          "trials": [{"name": t.name, "kept": t.kept, "reason": t.reason, "strokes": len(t.strokes),
                                      "rows": len(t.rows)} for t in ing.trials]}, indent=2))
        return 0
    print(f"{len(ing.dataset)} strokes from {len(kept)} of {len(ing.trials)} trial(s) -> {out}/data.csv "
          f"(card {out}/dataset.toml; every trial in {out}/trials.csv)")
    for t in ing.trials:
        if not t.kept:
            print(f"  rejected {t.name}: {t.reason}")
    if review:
        print(f"review page: {review}")
    print(f"next: skinfit fit MODEL {out} --out RUN_DIR")
    return 0
