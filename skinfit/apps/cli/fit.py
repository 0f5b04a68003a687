"""``skinfit fit MODEL DATASET --out RUN``: one fit (or one per group with ``--by``) written
to a run folder, with its summary."""

import json
import sys
import time
from pathlib import Path

from skinfit.analysis.groups import check_out_dir, fit_by, read_inputs
from skinfit.errors import InputError
from skinfit.inference.checkpoint import CheckpointLock
from skinfit.inference.run import resolve_inputs
from skinfit.io.data import load_dataset, write_card
from skinfit.results.fitting import fit

__all__ = ["run"]


def _parse_split(items):
    out = {}
    for item in items or []:
        name, sep, cols = item.partition("=")
        if not sep or not cols:
            raise InputError("--split", f"expected PARAMETER=COLUMN[,COLUMN] (got {item!r})")
        out[name] = cols.split(",")
    return out


def run(args):
    out = Path(args.out)
    split = _parse_split(args.split) or None
    if args.by:
        return _run_by(args, out, split)
    t0 = time.perf_counter()
    checkpoint = out / "checkpoint.h5"
    dataset = _cardless_csv(args)
    model, data, priors = resolve_inputs(args.model, dataset or args.dataset, args.priors)
    # results there are replaced only when asked (--overwrite), or continued (--resume)
    claim = dict(overwrite=args.overwrite, resume=args.resume, writes_card=dataset is not None)
    check_out_dir(out, model, priors, data, **claim)
    if args.resume and not checkpoint.exists():
        print(f"skinfit: no checkpoint {checkpoint} to resume: starting afresh", file=sys.stderr)
    with CheckpointLock(checkpoint):
        check_out_dir(out, model, priors, data, **claim)  # again, holding the lock: a run that ended meanwhile
        result = fit(model, data, priors=priors, rng=args.seed, split=split,
                     noise=args.noise, progress=not args.quiet,
                     ess_target=args.ess, max_steps=args.max_steps, checkpoint=checkpoint,
                     resume=args.resume, checkpoint_every=args.checkpoint_every)
        path = result.save(out / "fit.nc")  # still holding the lock: no other run sees the folder half written
        summary = result.summary(ci_prob=getattr(args, "ci", None))
        (out / "summary.csv").write_text(summary.to_csv())
        card = None
        if dataset is not None:  # a CSV without a card: its card and a copy beside the result
            card = write_card(dataset, out / "dataset")
    if args.json:
        print(json.dumps({"fit": str(path), "summary_csv": str(out / "summary.csv"), "model": result.model_id,
                          "dataset": result.dataset_id, "dataset_card": None if card is None else str(card),
                          "inputs": result.inputs,
                          "seed": int(result.attrs["seed"]),
                          "converged": bool(result.converged), "warnings": result.warnings, "notes": result.notes,
                          "summary": json.loads(summary.to_json(orient="index")),
                          "ci_prob": summary.attrs.get("ci_prob"), "ci_kind": summary.attrs.get("ci_kind"),
                          "seconds": time.perf_counter() - t0}, indent=2, default=str))
    else:
        print(result.report_text(summary))
        if card is not None:
            print(f"dataset card (rerun with it: skinfit fit {args.model} {out / 'dataset'}): {card}")
        print(f"\nwritten: {path} and {out / 'summary.csv'}  ({time.perf_counter() - t0:.1f} s)")
    if args.strict and result.warnings:  # failed or warned (skinfit.inference.guardrails): result kept, exit 3
        print(f"skinfit: --strict: {len(result.warnings)} guard-rail problem(s), see above", file=sys.stderr)
        return 3
    return 0


def _run_by(args, out, split):
    """``--by COLUMN``: one fit per group (:func:`skinfit.analysis.groups.fit_by`) and the index."""
    if args.resume:
        raise InputError("--resume", "not supported with --by yet: resume each group's run directory")

    dataset = _cardless_csv(args)
    index = fit_by(args.model, dataset or args.dataset, args.by, out, priors=args.priors, seed=args.seed,
                   split=split, noise=args.noise, progress=not args.quiet,
                   ess_target=args.ess, max_steps=args.max_steps, overwrite=args.overwrite,
                   writes_card=dataset is not None)
    if dataset is not None:  # a CSV without a card: its card and a copy beside the results
        print(f"dataset card: {write_card(dataset, out / 'dataset')}", file=sys.stderr if args.json else sys.stdout)
    if args.json:
        print(index.to_json(orient="records", indent=2))
    else:
        print("\n".join(read_inputs(out)) + "\n")  # the files every group's fit read
        print(index.to_string(index=False) + f"\n\nwritten: {out / 'index.json'}")
    failed = int((index["status"] != "done").sum())
    if failed:  # as a campaign: the other groups' results kept, exit 1
        print(f"skinfit: {failed} of {len(index)} group fit(s) failed, see above", file=sys.stderr)
        return 1
    warned = int((~index["converged"].astype(bool) | (index["warnings"] > 0)).sum())
    if args.strict and warned:  # as for a single fit: results kept, exit 3
        print(f"skinfit: --strict: {warned} group problem(s) (not converged or warned), see above",
              file=sys.stderr)
        return 3
    return 0


def _cardless_csv(args):
    """The Dataset of a CSV named without a card (units in its header), else None."""
    if Path(args.dataset).suffix.lower() not in (".csv", ".txt"):
        return None
    return load_dataset(args.dataset, model=args.model)
