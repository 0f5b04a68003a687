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


def test_skinfit_fit_in_a_new_process_saves_every_group(tmp_path):
    """``skinfit fit`` of the shipped electroadhesion dataset (units V and mN, read by the unit
    grammar of skinfit.io.units) in a new interpreter: the file holds every group and the misfit
    record."""
    out = tmp_path / "run"
    code = (f"from skinfit.apps.cli import main\nassert main(['fit', 'electroadhesion', 'electroadhesion_synthetic', "
            f"'--out', {str(out)!r}, '--seed', '1', '--quiet']) == 0\n")
    subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    from skinfit.results.fit import GROUPS, load_fit

    fit = load_fit(out)
    assert set(fit.idata.children) == set(GROUPS) - {"derived"} and fit.attr("misfit")["checks"]


def test_a_saved_fits_figures_import_what_each_needs(ea_fit, tmp_path):
    """A saved fit's figures drawn in a new interpreter, as by a report's figure worker: the
    trace and corner plots read its priors' bounds without scipy.stats (~0.5 s to import); the
    predictive check rebuilds the posterior without the sampler, the optimiser or ArviZ's tree
    builder (and draws the model's noiseless curves from it, not the fallback); the
    prior-against-posterior plot, which draws the densities, imports scipy.stats."""
    path = tmp_path / "fit.nc"
    ea_fit.save(path)
    code = ("import sys\nfrom skinfit.results.fit import load_fit\nfrom skinfit import plots\n"
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
