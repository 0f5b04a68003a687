"""A model added without editing skinfit (issue 22, point 3): the example plug-in package under
examples/skinfit-example-plugin registers its physics function through the ``skinfit.models``
entry point and brings its model card and prior file; skinfit lists it and fits it end to end,
recovering the parameters that generated the data.

scripts/setup.sh installs the plug-in; where it is not installed (``pip install -e ".[test]"``
alone, or the tests of an unpacked sdist) the tests install it for this process, as pip would:
its package folder and a ``.dist-info`` with its entry points on ``sys.path``."""

import importlib
import sys
import tomllib
from importlib.metadata import PackageNotFoundError, distribution
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import skinfit
from skinfit.io import registry

MU, F0, SIGMA = 0.45, 0.08, 0.01  # generating parameters [1], [N], [N]
PLUGIN = Path(__file__).resolve().parents[1] / "examples" / "skinfit-example-plugin"


def _dist_info(site, project):
    """A minimal installed-distribution record of ``project`` (its pyproject ``[project]``
    table) under ``site``: METADATA and entry_points.txt, what importlib.metadata reads."""
    info = site / f"{project['name'].replace('-', '_')}-{project['version']}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {project['name']}\nVersion: {project['version']}\n")
    lines = []
    for group, points in project.get("entry-points", {}).items():
        lines += [f"[{group}]", *(f"{name} = {value}" for name, value in points.items()), ""]
    (info / "entry_points.txt").write_text("\n".join(lines))


@pytest.fixture(scope="module", autouse=True)
def installed(tmp_path_factory):
    try:
        distribution("skinfit-example-plugin")
        yield  # installed (scripts/setup.sh): the tests use it as it is
        return
    except PackageNotFoundError:
        pass
    project = tomllib.loads((PLUGIN / "pyproject.toml").read_text())["project"]
    site = tmp_path_factory.mktemp("site")
    _dist_info(site, project)
    added = [str(site), str(PLUGIN)]
    sys.path[:0] = added
    importlib.invalidate_caches()
    registry._reset()  # skinfit reads the entry points again, now with the plug-in's
    try:
        assert distribution("skinfit-example-plugin").version == project["version"]
        yield
    finally:
        for entry in added:
            sys.path.remove(entry)
        for name in [m for m in sys.modules if m.split(".")[0] == "skinfit_example_plugin"]:
            del sys.modules[name]
        importlib.invalidate_caches()
        registry._reset()


def _data(rng, n=60):
    fn = np.linspace(0.2, 2.0, n)  # N
    ft = MU * fn + F0 + rng.normal(0.0, SIGMA, n)
    return pd.DataFrame({"subject": "S1", "normal_force [mN]": fn * 1e3, "tangential_force [mN]": ft * 1e3})


def test_plugin_model_and_priors_found_by_id():
    assert "example_two_term" in skinfit.list_models() and "example_two_term" in skinfit.list_priors()
    model = skinfit.load_model("example_two_term")
    assert model.parameter_names == ("mu", "F0")
    assert "two_term_friction" in registry.registered("forward")
    # the card's function is the plug-in's, not a copy: Derjaguin's law at a hand-computed point
    assert model.predict({"mu": 0.5, "F0": 0.1}, {"normal_force": np.array([1.0, 2.0])}) == pytest.approx([0.6, 1.1])


def test_plugin_model_fitted_end_to_end_recovers_its_generating_parameters(tmp_path):
    df = _data(np.random.default_rng(7))
    csv = tmp_path / "forces.csv"
    df.to_csv(csv, index=False)
    fit = skinfit.fit("example_two_term", str(csv), rng=3)
    assert fit.converged
    post = fit.idata["posterior"]
    for name, truth in {"mu": MU, "F0": F0, "sigma": SIGMA}.items():
        lo, hi = np.quantile(post[name].values, [0.005, 0.995])
        assert lo < truth < hi, (name, lo, hi)
    # an independent method: the least-squares line through the same data (the posterior mean of
    # a near-flat prior on a linear model equals it to a small fraction of its standard error)
    slope, intercept = np.polyfit(df["normal_force [mN]"] / 1e3, df["tangential_force [mN]"] / 1e3, 1)
    assert float(post["mu"].mean()) == pytest.approx(slope, abs=0.2 * float(post["mu"].std()))
    assert float(post["F0"].mean()) == pytest.approx(intercept, abs=0.2 * float(post["F0"].std()))
