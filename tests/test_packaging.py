"""skinfit as an installed package: search path, shipped files, CLI conveniences, result files."""

import json
import os
import re
import shutil
import stat
import subprocess
import sys
import tarfile
import warnings
import zipfile
from pathlib import Path

import pytest

import skinfit
import skinfit.io.paths
import skinfit.io.registry
from skinfit.apps.cli import main

ROOT = Path(skinfit.__file__).resolve().parents[1]
SHIPPED = {"models": sorted(p.stem for p in (ROOT / "models").glob("*.toml")),
           "priors": sorted(p.stem for p in (ROOT / "priors").glob("*.toml")),
           "datasets": sorted(p.parent.name for p in (ROOT / "datasets").glob("*/dataset.toml"))}


@pytest.fixture
def isolated(tmp_path, monkeypatch):
    """A search path with no $SKINFIT_PATH, no --path, no plug-in folders and an empty user
    folder under tmp_path."""
    monkeypatch.delenv("SKINFIT_PATH", raising=False)
    monkeypatch.setattr(skinfit.io.registry, "plugin_folders", list)
    monkeypatch.setattr(skinfit.io.paths, "user_root", lambda: tmp_path / "user")
    skinfit.io.paths.set_search_path([])
    yield tmp_path
    skinfit.io.paths.set_search_path([])


def _card(folder, model_id, title):
    """A copy of the shipped electroadhesion card under folder/models with another title."""
    text = (ROOT / "models" / "electroadhesion.toml").read_text()
    assert 'title = "' in text
    lines = [f'title = "{title}"' if line.startswith("title = ") else
             f'id = "{model_id}"' if line.startswith("id = ") else line for line in text.splitlines()]
    (folder / "models").mkdir(parents=True, exist_ok=True)
    path = folder / "models" / f"{model_id}.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_shipped_files_are_every_top_level_card_and_dataset(isolated):
    """What the search path lists from the shipped folder is exactly the repository's models/,
    priors/ and datasets/ (in a checkout read in place; in a wheel from skinfit/_shipped)."""
    for kind, ids in SHIPPED.items():
        found = skinfit.io.paths.entries(kind)
        assert sorted(found) == ids
        assert {e.root.origin for e in found.values()} == {"shipped"}


def test_search_path_precedence_explicit_then_env_then_user_then_shipped(isolated, monkeypatch):
    """The same id in every folder: --path wins, then $SKINFIT_PATH (in its order), then the
    user folder, then the shipped card; each later copy is listed as shadowed."""
    tmp = isolated
    explicit, env_a, env_b, user = tmp / "explicit", tmp / "env_a", tmp / "env_b", tmp / "user"
    for folder in (explicit, env_a, env_b, user):
        _card(folder, "electroadhesion", f"from {folder.name}")
    monkeypatch.setenv("SKINFIT_PATH", os.pathsep.join([str(env_a), str(env_b)]))
    skinfit.io.paths.set_search_path([explicit])
    assert skinfit.load_model("electroadhesion").title == "from explicit"
    entry = skinfit.io.paths.entries("models")["electroadhesion"]
    assert [r.origin for r in entry.shadows] == ["$SKINFIT_PATH", "$SKINFIT_PATH", "user", "shipped"]
    skinfit.io.paths.set_search_path([])
    assert skinfit.load_model("electroadhesion").title == "from env_a"
    monkeypatch.setenv("SKINFIT_PATH", str(env_b))
    assert skinfit.load_model("electroadhesion").title == "from env_b"
    monkeypatch.delenv("SKINFIT_PATH")
    assert skinfit.load_model("electroadhesion").title == "from user"
    shutil.rmtree(user / "models")
    assert skinfit.load_model("electroadhesion").title == (ROOT / "models" / "electroadhesion.toml").read_text() \
        .split('title = "', 1)[1].split('"', 1)[0]


def test_a_card_only_in_a_user_folder_is_listed_with_its_origin(isolated, capsys):
    _card(isolated / "user", "my_model", "my own electroadhesion copy")
    assert main(["models", "--verbose"]) == 0
    out = capsys.readouterr().out
    assert f"my_model: my own electroadhesion copy\n  from: {isolated / 'user' / 'models' / 'my_model.toml'} (user)" in out
    assert "search path (first match wins):" in out and f"{isolated / 'user' / 'models'}  (user)" in out
    assert main(["models", "--json"]) == 0
    rows = {r["id"]: r for r in json.loads(capsys.readouterr().out)}
    assert rows["my_model"]["origin"] == "user" and rows["electroadhesion"]["origin"] == "shipped"


@pytest.mark.parametrize("command", ["models", "datasets", "priors"])
def test_listing_nothing_says_so_and_exits_1(isolated, monkeypatch, capsys, command):
    monkeypatch.setattr(skinfit.io.paths, "shipped_root", lambda: None)
    assert main([command]) == 1
    captured = capsys.readouterr()
    assert captured.out == ""
    assert f"skinfit: no {command} found; searched:" in captured.err
    assert str(isolated / "user" / command) in captured.err


def test_version_prints_the_installed_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"skinfit {skinfit.__version__}"
    assert skinfit.__version__ != "0.0.0+unknown"


def test_models_piped_into_head_has_no_traceback(tmp_path):
    """`skinfit models | head -1`: the reader closes the pipe early; no BrokenPipeError text."""
    proc = subprocess.run(f"'{sys.executable}' -m skinfit models | head -n 1", shell=True, capture_output=True,
                          text=True, cwd=tmp_path, timeout=120)
    assert proc.stdout.startswith("contact_area:")
    assert "Traceback" not in proc.stderr and "BrokenPipe" not in proc.stderr


def test_refused_fit_leaves_no_empty_output_folder(tmp_path, capsys):
    out = tmp_path / "run" / "nested"
    assert main(["fit", "nope", "electroadhesion_synthetic", "--out", str(out)]) == 2
    assert not (tmp_path / "run").exists() or not out.exists()
    assert not out.exists()
    existing = tmp_path / "kept"
    existing.mkdir()
    assert main(["fit", "nope", "electroadhesion_synthetic", "--out", str(existing)]) == 2
    assert existing.is_dir()  # a folder the user made is not removed


def test_missing_optional_dependency_names_the_extra(monkeypatch):
    from skinfit.errors import MissingDependency, require_optional

    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails as if not installed
    with pytest.raises(MissingDependency, match=r"^distributed is not installed: install skinfit\[dask\]"):
        require_optional("distributed", "dask")


def test_warnings_print_one_line_without_the_source_line(tmp_path, capsys):
    from skinfit.apps.cli import _format_warning

    text = _format_warning(skinfit.ConvergenceWarning("E_star: 9% near the bound"), skinfit.ConvergenceWarning,
                           "/x/skinfit/fit.py", 152, "warnings.warn(msg)")
    assert text == "skinfit: ConvergenceWarning: E_star: 9% near the bound\n"


@pytest.fixture(scope="module")
def seeded_run(tmp_path_factory):
    """`skinfit fit ... --json` without --seed, run once for the tests below."""
    out = tmp_path_factory.mktemp("run") / "r"
    proc = subprocess.run([sys.executable, "-m", "skinfit", "fit", "electroadhesion_coulomb",
                           "electroadhesion_synthetic", "--out", str(out), "--quiet", "--json"],
                          capture_output=True, text=True, timeout=600, env={**os.environ, "MPLBACKEND": "Agg"})
    assert proc.returncode == 0, proc.stderr
    return out, json.loads(proc.stdout), proc.stderr


def test_fit_without_seed_draws_records_and_reproduces_it(seeded_run):
    """A seed is drawn, written in the result and the JSON, and refitting with it gives
    identical samples."""
    out, doc, _ = seeded_run
    saved = skinfit.load_fit(out / "fit.nc")
    seed = int(saved.attrs["seed"])
    assert seed >= 0 and doc["seed"] == seed and int(saved.attrs["seed_drawn"]) == 1
    assert f"seed: {seed} (drawn; --seed {seed} repeats this fit)" in saved.report_text()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again = skinfit.fit("electroadhesion_coulomb", "electroadhesion_synthetic", rng=seed)
    a = saved.idata["posterior"].to_dataset()
    b = again.idata["posterior"].to_dataset()
    for name in a.data_vars:
        assert (a[name].values == b[name].values).all()


def test_fit_json_is_the_summary_and_provenance(seeded_run):
    out, doc, _ = seeded_run
    assert doc["fit"] == str(out / "fit.nc") and doc["model"] == "electroadhesion_coulomb"
    summary = skinfit.load_fit(out / "fit.nc").summary()
    assert set(doc["summary"]) == set(summary.index)
    assert doc["summary"]["E_star"]["mean"] == pytest.approx(summary.loc["E_star", "mean"])


def test_result_files_follow_the_umask(tmp_path, seeded_run):
    """fit.nc is written through mkstemp (mode 0600) and renamed: it gets 0666 less the umask,
    as summary.csv beside it does."""
    out, _, _ = seeded_run
    fit = skinfit.load_fit(out / "fit.nc")
    for mask, mode in ((0o027, 0o640), (0o022, 0o644)):
        old = os.umask(mask)
        try:
            path = fit.save(tmp_path / oct(mask) / "fit.nc")
        finally:
            os.umask(old)
        assert stat.S_IMODE(path.stat().st_mode) == mode


def test_compare_leaves_its_inputs_byte_identical_unless_asked(tmp_path, seeded_run, capsys):
    out, _, _ = seeded_run
    first = tmp_path / "a.nc"
    shutil.copy(out / "fit.nc", first)
    second = tmp_path / "b.nc"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        skinfit.fit("electroadhesion", "electroadhesion_synthetic", rng=2, max_steps=4000).save(second)
    before = {p: p.read_bytes() for p in (first, second)}
    assert main(["compare", str(first), str(second), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["model"] for r in rows} == {"electroadhesion", "electroadhesion_coulomb"}
    assert all(p.read_bytes() == b for p, b in before.items())
    assert main(["compare", str(first), str(second), "--save-evidence"]) == 0
    assert "evidence" in skinfit.load_fit(first).attrs


def test_py_typed_marker_ships():
    assert (ROOT / "skinfit" / "py.typed").is_file()


@pytest.mark.slow
def test_wheel_carries_the_shipped_files(tmp_path):
    """The built wheel holds every shipped card, prior file and dataset under skinfit/_shipped,
    the references file and py.typed."""
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(ROOT)],
                   check=True, timeout=600)
    (wheel,) = tmp_path.glob("skinfit-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for kind, ids in SHIPPED.items():
        for i in ids:
            card = f"skinfit/_shipped/{kind}/{i}/dataset.toml" if kind == "datasets" else f"skinfit/_shipped/{kind}/{i}.toml"
            assert card in names
    assert "skinfit/py.typed" in names and "skinfit/references.toml" in names


#: Files outside tests/ that the tests read but the sdist leaves out, and why that is safe.
NOT_IN_SDIST = {"reports/example": "13 MB of figures; test_browser skips its check where it is absent"}


def _files_the_tests_read():
    """Repository paths outside tests/ that the test modules name as ``ROOT / "a" / "b"`` or
    ``Path(__file__).resolve().parents[1] / "a" / ...`` (found by reading them, so a new one is
    not forgotten), that exist here."""
    chain = re.compile(r'(?:ROOT|parents\[1\])((?:\s*/\s*"[^"\n]+")+)')
    found = set()
    for module in (ROOT / "tests").glob("*.py"):
        for m in chain.finditer(module.read_text()):
            parts = re.findall(r'"([^"]+)"', m.group(1))
            for k in range(len(parts), 0, -1):  # the longest prefix that exists (a file, or a folder)
                rel = "/".join(parts[:k])
                if (ROOT / rel).exists():
                    if parts[0] != "tests":
                        found.add(rel)
                    break
    return found


@pytest.mark.slow
def test_sdist_carries_every_file_its_tests_read(tmp_path):
    """The sdist's tests pass only if it holds what they read outside tests/ (bench/fused.py,
    the example plug-in, ...), whole: its include patterns are anchored at the root, so that
    "models" does not take a plug-in's cards/models alone, nor "README.md" every README."""
    pytest.importorskip("build", reason="building an sdist needs the `build` package (pip install build)")
    subprocess.run([sys.executable, "-m", "build", "--sdist", "-o", str(tmp_path), str(ROOT)], check=True,
                   timeout=600, capture_output=True)
    (sdist,) = tmp_path.glob("skinfit-*.tar.gz")
    with tarfile.open(sdist) as tar:
        names = {n.split("/", 1)[1] for n in tar.getnames() if "/" in n}
    needed = _files_the_tests_read()
    assert {"bench/fused.py", "examples/skinfit-example-plugin", "campaigns/example.toml"} <= needed
    for rel in sorted(needed - set(NOT_IN_SDIST)):
        path = ROOT / rel
        files = [path] if path.is_file() else [f for f in path.rglob("*") if f.is_file()
                                                and not any(part.endswith(".egg-info") or part == "__pycache__"
                                                            for part in f.relative_to(ROOT).parts)]
        missing = [str(f.relative_to(ROOT)) for f in files if str(f.relative_to(ROOT)) not in names]
        assert not missing, f"the sdist lacks {missing} (read by the tests)"
    assert not any(n.startswith("bench/results/") for n in names)  # "README.md" anchored: no stray READMEs


def test_fit_html_view_shows_verdict_warnings_and_summary(seeded_run):
    out, _, _ = seeded_run
    fit = skinfit.load_fit(out / "fit.nc")
    html = fit._repr_html_()
    assert ("converged</b>" in html) and (("NOT converged" in html) != fit.converged)
    for name in fit.summary().index:
        assert f"<th>{name}</th>" in html
    for w in fit.warnings:
        assert w["status"] in html
    assert f"seed {int(fit.attrs['seed'])}" in html


def test_report_json_names_the_report_and_its_fits(tmp_path, seeded_run, capsys):
    out, _, _ = seeded_run
    assert main(["report", str(out / "fit.nc"), "--out", str(tmp_path / "rep"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert Path(doc["report"]) == tmp_path / "rep" / "index.html" and Path(doc["report"]).is_file()
    assert len(doc["fits"]) == 1
    html = Path(doc["report"]).read_text()
    assert "Fujii" not in html and "Modeling Sliding Friction Between Human Finger and Touchscreen" in html


def test_compare_without_dynesty_says_which_extra_to_install(tmp_path, seeded_run, capsys, monkeypatch):
    out, _, _ = seeded_run
    monkeypatch.setitem(sys.modules, "dynesty", None)  # import fails as if not installed
    code = main(["compare", str(out / "fit.nc"), str(out / "fit.nc"), "--method", "nested"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.strip() == "skinfit: error: dynesty is not installed: install skinfit[nested] (pip install 'skinfit[nested]')"


def test_public_functions_are_annotated():
    """py.typed promises type hints: every public function of the top-level API annotates each
    parameter and its return (checked on the signatures, as a type checker reads them)."""
    import inspect

    names = ["load_model", "list_models", "load_priors", "list_priors", "load_dataset", "list_datasets", "fit",
             "load_fit", "compare", "evidence", "design"]
    for name in names:
        sig = inspect.signature(getattr(skinfit, name))
        missing = [p.name for p in sig.parameters.values()
                   if p.annotation is inspect.Parameter.empty and p.kind is not p.VAR_KEYWORD]
        assert not missing and sig.return_annotation is not inspect.Signature.empty, (name, missing)
    from skinfit.analysis.population.population import population

    assert inspect.signature(population).return_annotation == "PopulationResult"
    assert (Path(skinfit.__file__).parent / "py.typed").is_file()
