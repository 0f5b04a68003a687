"""Commands import only what they use: checked by import inspection in a fresh interpreter
(timings are in bench/bench_startup.py and bench/results/startup.md, not here)."""

import json
import os
import subprocess
import sys

import pytest

HEAVY = ("arviz", "arviz_base", "arviz_stats", "arviz_plots", "matplotlib", "dask", "distributed", "jinja2")


def _loaded(code):
    """Top-level package names in sys.modules after running ``code`` in a new interpreter."""
    probe = code + "\nimport json, sys\nprint(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


@pytest.mark.parametrize("code", ["import skinfit", "import skinfit.apps.cli",
                                  "from skinfit.apps.cli import main\nmain(['models'])"])
def test_import_skinfit_and_the_cli_load_no_arviz_matplotlib_dask_or_jinja2(code):
    loaded = _loaded(code)
    assert not loaded & set(HEAVY), sorted(loaded & set(HEAVY))
    assert not loaded & {"xarray", "scipy", "pandas", "emcee"}, "import skinfit / skinfit models stay light"


def test_fitting_modules_load_no_arviz_plots_matplotlib_or_jinja2():
    loaded = _loaded("import skinfit.results.fitting, skinfit.analysis.compare, skinfit.analysis.evidence, "
                     "skinfit.analysis.contrasts, skinfit.analysis.groups")
    assert not loaded & {"arviz", "arviz_plots", "matplotlib", "jinja2", "dask", "distributed"}


def test_public_names_resolve_lazily_to_the_functions_not_the_submodules():
    code = ("import skinfit, types\n"
            "skinfit.fit, skinfit.compare, skinfit.evidence, skinfit.Fit\n"
            "assert callable(skinfit.fit) and not isinstance(skinfit.fit, types.ModuleType)\n"
            "assert skinfit.fit is sys.modules['skinfit.results.fitting'].fit\n"
            "assert skinfit.compare is sys.modules['skinfit.analysis.compare'].compare\n"
            "assert skinfit.evidence is sys.modules['skinfit.analysis.evidence'].evidence\n"
            "assert skinfit.Fit is sys.modules['skinfit.results.fit'].Fit\n"
            "assert set(skinfit.__all__) <= set(dir(skinfit))")
    subprocess.run([sys.executable, "-c", "import sys\n" + code], check=True)


def test_skinfit_fit_builds_no_unit_registry_and_imports_no_dask_or_pint(tmp_path):
    """``skinfit fit`` of the shipped electroadhesion dataset (units V and mN): the units are read
    without pint's UnitRegistry, and neither Dask nor pint is imported: not by xarray's writer
    (to look for a scheduler), nor by xarray's first array (for their array types);
    afterwards ``distributed`` imports as usual, and the file holds every group."""
    out = tmp_path / "run"
    code = (f"from skinfit.apps.cli import main\nassert main(['fit', 'electroadhesion', 'electroadhesion_synthetic', "
            f"'--out', {str(out)!r}, '--seed', '1', '--quiet']) == 0\n"
            "import skinfit.io.units\nprint('registry', skinfit.io.units._REGISTRY)\n"
            "print('distributed imported', 'distributed' in sys.modules)\n"
            "print('dask or pint imported', sorted({m.split('.')[0] for m in sys.modules} & {'dask', 'pint'}))\n"
            "import distributed\n")
    probe = "import sys\n" + code
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert "registry None" in result.stdout and "distributed imported False" in result.stdout
    assert "dask or pint imported []" in result.stdout
    from skinfit.results.fit import GROUPS, load_fit

    fit = load_fit(out)
    assert set(fit.idata.children) == set(GROUPS) - {"derived"} and fit.attr("misfit")["checks"]


def test_xarray_still_tells_dask_arrays_and_pint_quantities_apart_after_skinfit_deferred_them(ea_fit, tmp_path):
    """Arrays built before dask and pint are imported do not import them; a dask array or pint
    Quantity made afterwards is still one to xarray (lazy, chunked and shown as such; units
    kept and taken off by xarray, not stripped by numpy), and a fit saved then holds the same."""
    code = ("import numpy as np, skinfit.fit, xarray as xr\n"
            "x = xr.DataArray(np.arange(3.0), dims='i').sum()\n"
            "fit = sys.modules['skinfit.results.fit'].load_fit(sys.argv[1])\n"
            "fit.save(sys.argv[2])\n"
            "assert not {m.split('.')[0] for m in sys.modules} & {'dask', 'pint'}\n"
            "from xarray.namedarray import pycompat\n"
            "sys.modules['dask'] = None  # as while Fit.save writes: a question then is not the last word\n"
            "assert pycompat.mod_version('dask').major == 0\n"
            "del sys.modules['dask']\n"
            "import dask.array as da\n"
            "y = xr.DataArray(da.arange(6.0, chunks=2), dims='i')\n"
            "assert isinstance(y.data, da.Array) and y.chunks == ((2, 2, 2),)\n"
            "s = xr.Dataset({'y': y}).y.sum()\n"
            "assert isinstance(s.data, da.Array) and float(s.compute()) == 15.0\n"
            "assert 'dask.array<chunksize=(2,)' in repr(xr.Dataset({'y': y}))\n"
            "z = xr.DataArray(np.ones(4), dims='i').chunk(2)\n"
            "assert isinstance(z.data, da.Array) and z.chunks == ((2, 2),)\n"
            "import pint\n"
            "q = xr.DataArray(pint.UnitRegistry().Quantity(np.arange(3.0), 'mN'), dims='i')\n"
            "assert isinstance(q.data, pint.Quantity) and str(q.data.units) == 'millinewton'\n"
            "assert float((q * 2).sum().data.magnitude) == 6.0\n"
            "import warnings\n"
            "with warnings.catch_warnings():\n"
            "    warnings.simplefilter('error')  # units stripped by numpy would warn\n"
            "    assert q.to_numpy().tolist() == [0.0, 1.0, 2.0]\n"
            "fit.save(sys.argv[3])\n"
            "trees = [xr.open_datatree(p, engine='h5netcdf') for p in sys.argv[2:]]\n"
            "assert trees[0].identical(trees[1])  # same content (h5py 3.12 stamps groups with the time)\n")
    saved = ea_fit.save(tmp_path / "fit.nc")
    subprocess.run([sys.executable, "-c", "import sys\n" + code, str(saved), str(tmp_path / "without_dask.nc"),
                    str(tmp_path / "with_dask.nc")], check=True)


def test_a_saved_fits_figures_import_what_each_needs(ea_fit, tmp_path):
    """A saved fit's figures drawn in a new interpreter, as by a report's figure worker: the
    trace and corner plots read its priors' bounds without scipy.stats (~0.5 s to import); the
    predictive check rebuilds the posterior without the sampler, the optimiser or ArviZ's tree
    builder (and draws the model's noiseless curves from it, not the fallback); the
    prior-against-posterior plot, which draws the densities, imports scipy.stats."""
    path = tmp_path / "fit.nc"
    ea_fit.save(path)
    code = ("import sys\nfrom skinfit.results.fit import load_fit\nfrom skinfit.plots import figures as plots\n"
            "fit = load_fit(sys.argv[1])\n"
            "plots.plot_trace(fit), plots.plot_pair(fit)\n"
            "print('trace, pair:', 'scipy.stats' in sys.modules)\n"
            "import warnings\nwarnings.simplefilter('error')  # a fallback without the posterior would warn\n"
            "fig = plots.plot_ppc(fit)\n"
            "curves = [l for a in fig.axes for l in a.lines if l.get_gid() == 'median' and l.get_linestyle() == '-']\n"
            "print('ppc curves:', len(curves))\n"
            "print('ppc:', sorted({m.split('.')[0] for m in sys.modules} & {'emcee', 'nlopt', 'arviz_base'}))\n"
            "plots.plot_prior_posterior(fit)\n"
            "print('prior_posterior:', 'scipy.stats' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, check=True,
                         env={**os.environ, "MPLBACKEND": "Agg"}).stdout
    assert "trace, pair: False" in out and "ppc: []" in out and "prior_posterior: True" in out, out
    # the posterior was rebuilt: the electroadhesion check's noiseless median curve, one per voltage level
    n_curves = int(out.split("ppc curves: ")[1].split()[0])
    assert n_curves == ea_fit.idata["constant_data"]["voltage"].to_series().nunique(), out
