"""Commands import only what they use: checked by import inspection in a fresh interpreter
(timings are in bench/bench_startup.py and bench/results/startup.md, not here)."""

import json
import subprocess
import sys

import pytest

HEAVY = ("arviz", "arviz_base", "arviz_stats", "arviz_plots", "matplotlib", "dask", "distributed", "jinja2")


def _loaded(code):
    """Top-level package names in sys.modules after running ``code`` in a new interpreter."""
    probe = code + "\nimport json, sys\nprint(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


@pytest.mark.parametrize("code", ["import skinfit", "import skinfit.cli",
                                  "from skinfit.cli import main\nmain(['models'])"])
def test_import_skinfit_and_the_cli_load_no_arviz_matplotlib_dask_or_jinja2(code):
    loaded = _loaded(code)
    assert not loaded & set(HEAVY), sorted(loaded & set(HEAVY))
    assert not loaded & {"xarray", "scipy", "pandas", "emcee"}, "import skinfit / skinfit models stay light"


def test_fitting_modules_load_no_arviz_plots_matplotlib_or_jinja2():
    loaded = _loaded("import skinfit.fit, skinfit.compare, skinfit.evidence, skinfit.contrasts, skinfit.groups")
    assert not loaded & {"arviz", "arviz_plots", "matplotlib", "jinja2", "dask", "distributed"}


def test_public_names_resolve_lazily_to_the_functions_not_the_submodules():
    code = ("import skinfit, skinfit.fit, skinfit.compare, skinfit.evidence, types\n"
            "assert callable(skinfit.fit) and not isinstance(skinfit.fit, types.ModuleType)\n"
            "assert skinfit.fit is sys.modules['skinfit.fit'].fit\n"
            "assert skinfit.compare is sys.modules['skinfit.compare'].compare\n"
            "assert skinfit.evidence is sys.modules['skinfit.evidence'].evidence\n"
            "assert skinfit.Fit is sys.modules['skinfit.fit'].Fit\n"
            "assert set(skinfit.__all__) <= set(dir(skinfit))")
    subprocess.run([sys.executable, "-c", "import sys\n" + code], check=True)


def test_skinfit_fit_builds_no_unit_registry_and_leaves_distributed_alone(tmp_path):
    """``skinfit fit`` of the shipped electroadhesion dataset (units V and mN): the units are read
    without pint's UnitRegistry, and writing fit.nc does not import Dask's ``distributed``
    (which xarray's writer imports to look for a scheduler); afterwards ``distributed`` imports
    as usual, and the file holds every group."""
    out = tmp_path / "run"
    code = (f"from skinfit.cli import main\nassert main(['fit', 'electroadhesion', 'electroadhesion_synthetic', "
            f"'--out', {str(out)!r}, '--seed', '1', '--quiet']) == 0\n"
            "import skinfit.units\nprint('registry', skinfit.units._REGISTRY)\n"
            "print('distributed imported', 'distributed' in sys.modules)\n"
            "import distributed\n")
    probe = "import sys\n" + code
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert "registry None" in result.stdout and "distributed imported False" in result.stdout
    from skinfit.fit import GROUPS, load_fit

    fit = load_fit(out)
    assert set(fit.idata.children) == set(GROUPS) - {"derived"} and fit.attr("misfit")["checks"]
