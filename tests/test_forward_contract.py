"""A model's forward function keeps its contract (skinfit.io.forward_check) or the fit stops in one line.

Issue 39, point 14: a plug-in forward that returned NaN, inf, the wrong shape or type, a dict
without an observable, raised, or mixed up the parameter draws of a batch ended in a traceback
from inside numpy, nlopt or emcee -- or, not vectorised, in a silently wrong fit.  Each such
function is registered here in-process (skinfit.io.registry.register, no installed package
needed) under a copy of the example plug-in's card, and fitted: a ForwardError naming the card,
the function and what was expected vs got, raised before the MAP search starts.  A NaN met
only while sampling is the same one-line error, naming the parameter point and the data row.
"""

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import skinfit
from skinfit.errors import ForwardError, InputError
from skinfit.io import registry
from skinfit.io.forward_check import CHECK_DRAWS

ROOT = Path(skinfit.__file__).resolve().parents[1]
CARDS = ROOT / "examples" / "skinfit-example-plugin" / "skinfit_example_plugin" / "cards"
run_module = __import__("importlib").import_module("skinfit.inference.run")
N_ROWS = 40


def _good(p, x, c):
    """Derjaguin's two-term law (the example plug-in's), vectorised: F_t = mu F_n + F0, (k, n)."""
    ft = p["mu"] * x["normal_force"] + p["F0"]
    ft = np.broadcast_to(ft, np.broadcast_shapes(np.shape(ft), (1, len(x["normal_force"]))))
    return {"tangential_force": ft}, np.ones(ft.shape, dtype=bool)


def _k(p):
    return len(p["mu"])


def _ft(p, x):
    return _good(p, x, None)[0]["tangential_force"]


#: class -> (a forward function breaking the contract that way, what the error must say)
BROKEN = {
    "nan": (lambda p, x, c: ({"tangential_force": np.full((_k(p), len(x["normal_force"])), np.nan)}, True),
            r"returned nan for 'tangential_force' at data row 1 with parameters \{mu=.*\}, a point it marks valid"),
    "inf": (lambda p, x, c: ({"tangential_force": np.where(p["mu"] > 0, np.inf, _ft(p, x))}, True),
            r"returned inf for 'tangential_force' at data row 1 .* marks valid \(ok True\)"),
    "wrong_shape": (lambda p, x, c: ({"tangential_force": np.zeros((_k(p), 3))}, True),
                    rf"returned 'tangential_force' of shape \({CHECK_DRAWS}, 3\); "
                    rf"expected \({CHECK_DRAWS}, {N_ROWS}\)"),
    "transposed": (lambda p, x, c: ({"tangential_force": _ft(p, x).T}, True),
                   rf"returned 'tangential_force' of shape \({N_ROWS}, {CHECK_DRAWS}\); "
                   rf"expected \({CHECK_DRAWS}, {N_ROWS}\)"),
    "not_a_tuple": (lambda p, x, c: {"tangential_force": _ft(p, x)}, r"returned dict .*; expected a tuple \(y, ok\)"),
    "none": (lambda p, x, c: None, r"returned None; expected a tuple \(y, ok\)"),
    "not_a_dict": (lambda p, x, c: (_ft(p, x), True), r"returned y = ndarray .*; expected a dict observable"),
    "missing_observable": (lambda p, x, c: ({"friction": _ft(p, x)}, True),
                           r"returned no 'tangential_force' \(keys: 'friction'\); expected every observable"),
    "list": (lambda p, x, c: ({"tangential_force": _ft(p, x).tolist()}, True),
             r"returned 'tangential_force' as list .*; expected a numpy array of real numbers"),
    "text": (lambda p, x, c: ({"tangential_force": np.array(["1.0"] * len(x["normal_force"]))}, True),
             r"returned 'tangential_force' of dtype <U3 .*; expected real numbers"),
    "complex": (lambda p, x, c: ({"tangential_force": _ft(p, x) + 1j}, True),
                r"returned 'tangential_force' of dtype complex128 .*; expected real numbers"),
    "objects": (lambda p, x, c: ({"tangential_force": np.full((_k(p), len(x["normal_force"])), None)}, True),
                r"returned 'tangential_force' of dtype object .*; expected real numbers"),
    "ok_float": (lambda p, x, c: (_good(p, x, c)[0], np.full((_k(p), len(x["normal_force"])), 0.5)),
                 r"returned ok = ndarray .* of dtype float64; expected a bool array"),
    "ok_wrong_shape": (lambda p, x, c: (_good(p, x, c)[0], np.ones(5, dtype=bool)),
                       rf"returned ok of shape \(5,\); expected \({CHECK_DRAWS}, {N_ROWS}\)"),
    "raises": (lambda p, x, c: 1 / 0, r"raised ZeroDivisionError: division by zero \(called on 3 prior draws"),
    "scalar_only": (lambda p, x, c: ({"tangential_force": float(p["mu"]) * x["normal_force"]}, True),
                    r"raised TypeError: .* \(called on 3 prior draws"),
    # the silent one: parameters of the first draw used for every draw (a plain loop gone wrong)
    "first_draw_only": (lambda p, x, c: ({"tangential_force": np.ravel(p["mu"])[0] * x["normal_force"]
                                          + np.ravel(p["F0"])[0]}, True),
                        r"is not vectorised over parameter draws: its row 2 of 3 draws .* differs from draw 2"),
    # draws mixed up: row i computed from draw k-1-i
    "draws_reversed": (lambda p, x, c: ({"tangential_force": _ft({k: v[::-1] for k, v in p.items()}, x)}, True),
                       r"is not vectorised over parameter draws"),
}


@pytest.fixture(scope="module")
def data_csv(tmp_path_factory):
    rng = np.random.default_rng(5)
    fn = np.linspace(0.2, 2.0, N_ROWS)
    path = tmp_path_factory.mktemp("forward") / "forces.csv"
    ft = 0.45 * fn + 0.08 + rng.normal(0, 0.01, N_ROWS)
    pd.DataFrame({"subject": "S1", "normal_force [mN]": fn * 1e3, "tangential_force [mN]": ft * 1e3}).to_csv(path,
                                                                                                       index=False)
    return path


def _card(folder, card_id, forward_name):
    """A copy of the example plug-in's card (id ``card_id``, naming forward ``forward_name``) and
    prior file, in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    card = (CARDS / "models" / "example_two_term.toml").read_text()
    card = card.replace('"skinfit_example_plugin:two_term_friction"', f'"{forward_name}"').replace(
        'id = "example_two_term"', f'id = "{card_id}"')
    (folder / "m.toml").write_text(card)
    priors = (CARDS / "priors" / "example_two_term.toml").read_text().replace('"example_two_term"', f'"{card_id}"')
    (folder / "p.toml").write_text(priors)
    return folder / "m.toml", folder / "p.toml"


@pytest.fixture
def card(tmp_path):
    names = []

    def make(name, forward):
        registry.register("forward", name, forward)
        names.append(name)
        return _card(tmp_path / name, name, name)

    yield make
    for name in names:
        registry.unregister("forward", name)


def _no_fit(*args, **kwargs):
    raise AssertionError("the MAP search started with a broken forward function")


@pytest.mark.parametrize("kind", sorted(BROKEN))
def test_class_forward_contract_broken_function_refused_before_the_map(kind, card, data_csv, monkeypatch):
    forward, message = BROKEN[kind]
    model, priors = card(f"broken_{kind}", forward)
    monkeypatch.setattr(run_module, "find_map", _no_fit)
    with pytest.raises(ForwardError, match=rf"^{re.escape(str(model))}: forward: broken_{kind}: {message}") as info:
        skinfit.fit(str(model), str(data_csv), priors=str(priors), rng=1)
    assert "\n" not in str(info.value)


def test_class_forward_contract_the_example_plugins_function_passes(card, data_csv, monkeypatch):
    """Negative control: the contract's check accepts a correct function (and the MAP starts)."""
    model, priors = card("two_term_ok", _good)
    monkeypatch.setattr(run_module, "find_map", _no_fit)
    with pytest.raises(AssertionError, match="MAP search started"):
        skinfit.fit(str(model), str(data_csv), priors=str(priors), rng=1)


def test_class_forward_contract_every_shipped_model_passes_on_its_dataset():
    """The check refuses no shipped model on a shipped dataset it can be fitted to."""
    from skinfit.posterior import Posterior

    checked = 0
    for m in skinfit.list_models():
        model, priors = skinfit.load_model(m), skinfit.load_priors(m)
        for d in skinfit.list_datasets():
            ds = skinfit.load_dataset(d)
            if ds.model not in {m, *model.variants} and m not in skinfit.load_model(ds.model).variants:
                continue
            Posterior(model, priors, ds)
            checked += 1
    assert checked >= 15


def test_class_forward_contract_undefined_points_marked_ok_false_are_allowed(card, data_csv, monkeypatch):
    """NaN where the function says the model is undefined (ok False) is the contract, not a breach."""
    def partly_defined(p, x, c):
        y, ok = _good(p, x, c)
        ok = np.broadcast_to(x["normal_force"] < 1.5, y["tangential_force"].shape)
        return {"tangential_force": np.where(ok, y["tangential_force"], np.nan)}, ok

    model, priors = card("partly_defined", partly_defined)
    monkeypatch.setattr(run_module, "find_map", _no_fit)
    with pytest.raises(AssertionError, match="MAP search started"):
        skinfit.fit(str(model), str(data_csv), priors=str(priors), rng=1)


def _nan_above(p, x, c):
    """Correct below mu = 1, NaN above: the prior draws the check uses (quantiles 0.1 .. 0.9 of
    normal(0.5, 0.3) on [0, 2], mu <= 0.9) pass; ~5% of the MAP search's 2000 prior draws do not."""
    y, ok = _good(p, x, c)
    return {"tangential_force": np.where(p["mu"] > 1.0, np.nan, y["tangential_force"])}, ok


def test_class_forward_nan_met_while_fitting_is_one_line_naming_point_and_row(card, data_csv):
    model, priors = card("nan_above", _nan_above)
    with pytest.raises(ForwardError, match=rf"^{re.escape(str(model))}: forward: nan_above: returned nan for "
                                           r"'tangential_force' at data row 1 with parameters "
                                           r"\{mu=[1-9][\d.]*, F0=.*\}, a point it marks valid \(ok True\), "
                                           r"while fitting"):
        skinfit.fit(str(model), str(data_csv), priors=str(priors), rng=1)


def test_class_forward_nan_while_sampling_stops_emcee_without_its_traceback(capsys):
    """emcee prints a traceback for any exception of the target: the sampler keeps the error,
    ends the step and raises it itself."""
    from skinfit.inference.sampling import run_emcee

    class Target:
        calls = 0

        def __call__(self, z):
            Target.calls += 1
            if Target.calls > 3:
                raise InputError("m.toml", "stand-in for a forward function's NaN", field="forward")
            return -0.5 * (z ** 2).sum(axis=1)

    rng = np.random.default_rng(1)
    with pytest.raises(InputError, match="stand-in"):
        run_emcee(Target(), rng.normal(size=(8, 2)), rng, max_steps=50, check_every=10)
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err + captured.out and "emcee: Exception" not in captured.out


def test_class_forward_error_raised_inside_nlopt_is_itself_not_a_systemerror():
    from skinfit.inference.optimize import _nlopt

    def objective(w, grad):
        if w[0] > 0.6:
            raise InputError("m.toml", "raised by the objective", field="forward")
        if grad.size:
            grad[:] = -2 * (w - 0.9)
        return float(-np.sum((w - 0.9) ** 2))

    import nlopt

    for algorithm in (nlopt.LD_SLSQP, nlopt.LN_BOBYQA):
        with pytest.raises(InputError, match="raised by the objective"):
            _nlopt(algorithm, objective, np.array([0.5, 0.5]), 100, 1e-7, 0.05)


def test_class_forward_error_crosses_a_process_boundary():
    import pickle

    err = ForwardError("m.toml", "broken: returned nan", field="forward")
    again = pickle.loads(pickle.dumps(err))
    assert type(again) is ForwardError and str(again) == str(err) == "m.toml: forward: broken: returned nan"


def test_class_forward_contract_predict_names_nan_at_a_valid_point(card):
    model_path, _ = card("nan_predict", BROKEN["nan"][0])
    model = skinfit.load_model(str(model_path))
    with pytest.raises(ForwardError, match=r"returned nan for 'tangential_force' at row 1 of draw 1, a point it marks"):
        model.predict({"mu": 0.5, "F0": 0.1}, {"normal_force": np.array([1.0, 2.0])})
    # the caller's NaN, not the function's
    with pytest.raises(InputError, match=r"params\.mu: expected finite numbers"):
        model.predict({"mu": float("nan"), "F0": 0.1}, {"normal_force": np.array([1.0])})


def test_class_forward_contract_cli_one_line_error(data_csv, tmp_path):
    """Through the command line (a subprocess that registers the function, then runs
    ``skinfit fit`` on a card naming it): exit 2, one 'skinfit: error:' line, no traceback."""
    script = tmp_path / "run.py"
    script.write_text(
        "import sys, numpy as np\n"
        "from skinfit.io import registry\n"
        "from skinfit.apps.cli import main\n"
        "def wrong(p, x, c):\n"
        "    return {'tangential_force': np.zeros((len(p['mu']), 3))}, True\n"
        "registry.register('forward', 'cli_wrong_shape', wrong)\n"
        "sys.exit(main(sys.argv[1:]))\n")
    model, priors = _card(tmp_path / "cli", "cli_wrong_shape_card", "cli_wrong_shape")
    proc = subprocess.run([sys.executable, str(script), "fit", str(model), str(data_csv), "--priors", str(priors),
                           "--out", str(tmp_path / "run"), "--quiet"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"skinfit: error: {model}: forward: cli_wrong_shape: returned "
                                                   "'tangential_force' of shape (3, 3)")
    assert not (tmp_path / "run").exists()
