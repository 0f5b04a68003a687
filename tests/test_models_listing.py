"""One bad plug-in does not break the others (issue 42, point 5): ``skinfit models`` lists every
card it can read and names each it cannot, and each broken entry point, with the reason; exit 0
with the warnings, 1 with ``--strict``.  The plug-ins are installed for this process as pip
would: a package folder and a ``.dist-info`` with its entry points on ``sys.path``."""

import importlib
import sys
import textwrap

import pytest

from skinfit.apps.cli import main
from skinfit.io import registry

GOOD_CARD = textwrap.dedent('''\
    schema_version = 1
    id = "listing_good"
    title = "A plug-in model that reads"
    source = "my notes, eq. 1"
    forward = "listing_plug:linear"

    [[observables]]
    name = "tangential_force"
    unit = "N"

    [[covariates]]
    name = "normal_force"
    unit = "N"

    [[parameters]]
    name = "mu"
    unit = "1"
    ''')


@pytest.fixture
def broken_plugins(tmp_path):
    """Two installed plug-ins: ``listing_plug`` with two good cards (one naming a forward function,
    one a plain ``f(p, x)``) and a card naming a function it does not register, and ``listing_gone``, whose entry point names a module that is not there."""
    site = tmp_path / "site"
    (site / "listing_plug" / "cards" / "models").mkdir(parents=True)
    (site / "listing_plug" / "__init__.py").write_text(textwrap.dedent('''\
        from pathlib import Path
        import numpy as np

        def linear(p, x, c):
            return {"tangential_force": p["mu"] * x["normal_force"]}, np.ones((1, 1), bool)

        def power(p, x):
            return p["mu"] * x["normal_force"] ** 0.8

        CARDS = {"forward": {"listing_linear": linear}, "function": {"listing_power": power},
                 "folder": Path(__file__).parent / "cards"}
        '''))
    models = site / "listing_plug" / "cards" / "models"
    (models / "listing_good.toml").write_text(GOOD_CARD)
    (models / "listing_bad.toml").write_text(GOOD_CARD.replace("listing_good", "listing_bad")
                                             .replace("listing_plug:linear", "listing_plug:quadratic"))
    (models / "listing_own.toml").write_text(GOOD_CARD.replace("listing_good", "listing_own").replace(
        'forward = "listing_plug:linear"', 'function = "listing_plug:power"'))  # a user's f(p, x), as to_card writes
    for name, value in (("listing_plug", "listing_plug:CARDS"), ("listing_gone", "listing_gone_module:CARDS")):
        info = site / f"{name}-1.0.dist-info"
        info.mkdir()
        (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n")
        (info / "entry_points.txt").write_text(f"[skinfit.models]\n{name} = {value}\n")
    sys.path.insert(0, str(site))
    importlib.invalidate_caches()
    registry._reset()
    try:
        yield
    finally:
        sys.path.remove(str(site))
        sys.modules.pop("listing_plug", None)
        importlib.invalidate_caches()
        registry._reset()


def test_a_broken_card_and_plugin_are_named_not_fatal(broken_plugins, capsys):
    assert main(["models"]) == 0
    out, err = capsys.readouterr()
    assert "listing_good: A plug-in model that reads" in out and "source: my notes, eq. 1" in out
    assert "electroadhesion:" in out and "listing_bad:" not in out  # the shipped ones are listed too
    assert "listing_own: A plug-in model that reads" in out  # a card naming a plug-in's f(p, x)
    warnings = err.strip().splitlines()
    assert len(warnings) == 2, err
    assert any("listing_gone" in w and "fails to import: ModuleNotFoundError" in w for w in warnings)
    assert any("listing_bad.toml" in w and "'listing_plug:quadratic' is not a registered forward function" in w
               for w in warnings)
    assert all(w.startswith("skinfit models: warning: ") for w in warnings)


def test_strict_exits_non_zero(broken_plugins, capsys):
    assert main(["models", "--strict"]) == 1
    assert "listing_good" in capsys.readouterr().out


def test_no_warning_without_broken_cards(capsys):
    assert main(["models"]) == 0
    assert capsys.readouterr().err == ""
