"""Sizes of saved fits with and without their pointwise groups, the time to read those groups
from a file against computing them again, and PSIS-LOO from float64, float32 and recomputed
groups (bench/results/run_size.md).

    python bench/bench_run_size.py RUN_DIR...    # folders of fit.nc saved by a skinfit that stored the groups

For each fit.nc below the folders: its size; the size of the same tree written without the two
pointwise groups (what Fit.save writes now, less a recipe of ~300 bytes); the seconds to read
the groups from the file (load_fit, first use) and to compute them from the draws
(Posterior.replicate, the call skinfit.results.pointwise makes; the predictive draws' seed is
not in these older files, so the stored log-likelihood is compared bit for bit, the predictive
draws by time only); PSIS-LOO (arviz_stats.loo) from the stored float64 groups, from the same
cast to float32, and from the recomputed ones.
"""

import glob
import sys
import time
import warnings

import numpy as np
import xarray as xr

from skinfit.analysis.compare import loo
from skinfit.analysis.evidence import posterior_draws
from skinfit.results.fit import DEFERRED, Fit, load_fit
from skinfit.results.store import write_tree


def _loo(tree):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lo = loo(Fit(tree))
    return float(lo.elpd), float(lo.se)


def main(folders):
    rows, tot_old, tot_new = [], 0, 0
    for path in sorted(p for f in folders for p in glob.glob(f"{f}/**/fit.nc", recursive=True)):
        fit = load_fit(path)
        t0 = time.perf_counter()
        tree = fit.idata
        t_read = time.perf_counter() - t0
        light = xr.DataTree.from_dict({"/": tree.to_dataset(inherit=False)}
                                      | {n: tree[n].to_dataset(inherit=False) for n in tree.children
                                         if n not in DEFERRED})
        new_path = "/tmp/bench_run_size_light.nc"
        write_tree(light, new_path)
        size_old, size_new = len(open(path, "rb").read()), len(open(new_path, "rb").read())
        again = load_fit(path)
        t0 = time.perf_counter()
        post = again.posterior
        ll, _ = post.replicate(posterior_draws(again), np.random.default_rng(0))
        t_again = time.perf_counter() - t0
        stored = tree["log_likelihood"].to_dataset()
        same = all(np.array_equal(ll[o], stored[o].values.reshape(-1, post.n)) for o in ll)
        f32 = tree.copy()
        f32["log_likelihood"] = xr.DataTree(stored.astype(np.float32))
        recomputed = tree.copy()
        recomputed["log_likelihood"] = xr.DataTree(xr.Dataset(
            {o: (stored[o].dims, ll[o].reshape(stored[o].shape)) for o in ll}, coords=stored.coords))
        (e64, se), (e32, _), (e_re, _) = _loo(tree), _loo(f32), _loo(recomputed)
        name = path.split("/", 3)[-1] if path.startswith("/tmp/") else path
        rows.append(f"| {name} | {size_old / 1e6:.2f} | {size_new / 1e6:.2f} | {t_read:.2f} | {t_again:.2f} | "
                    f"{e64:.3f} ± {se:.2f} | {e32 - e64:+.1e} | {e_re - e64:+.1e} | {'yes' if same else 'NO'} |")
        print(rows[-1], flush=True)
        tot_old, tot_new = tot_old + size_old, tot_new + size_new
    print(f"\ntotal of {len(rows)} fits: {tot_old / 1e6:.1f} MB stored, {tot_new / 1e6:.1f} MB without the groups")


if __name__ == "__main__":
    main(sys.argv[1:])
