"""``skinfit campaign CAMPAIGN.toml``: run a campaign file (:mod:`skinfit.apps.campaign`) and
print its index."""

import json
import sys
import time

import pandas as pd

from skinfit.apps.campaign import load_campaign, run_campaign
from skinfit.inference.workers import check_scheduler

__all__ = ["run"]


def run(args):
    t0 = time.perf_counter()
    check_scheduler(args.scheduler)  # before the campaign's cards and data are read
    campaign = load_campaign(args.campaign)
    as_json = getattr(args, "json", False)
    echo = (lambda *a, **k: print(*a, **k, file=sys.stderr)) if as_json else print
    table = run_campaign(campaign, scheduler=args.scheduler, workers=args.workers,
                         threads=getattr(args, "threads", None), echo=echo)
    failed = ~table["status"].isin(["done", "complete"])
    if as_json:
        print(json.dumps({"index": str(campaign.out / "index.csv"), "failed": int(failed.sum()),
                          "fits": json.loads(table.to_json(orient="records"))}, indent=2))
        return 1 if failed.any() else 0
    with pd.option_context("display.width", 200, "display.max_columns", 20, "display.max_colwidth", 60):
        print(table.drop(columns=["path", "worker", "threads", "dataset_path", "dataset_sha256"])
              .to_string(index=False))
    unconverged = sum(c is False for c in table["converged"])
    print(f"\n{int((~failed).sum())} of {len(table)} fits complete ({unconverged} not converged), "
          f"{int(failed.sum())} failed; index: {campaign.out / 'index.csv'}  ({time.perf_counter() - t0:.1f} s)")
    return 1 if failed.any() else 0
