"""The import contract of the layers (docs/design/layers.md): read from the source's syntax
trees, so an import inside a function counts as much as one at the top of a module.

Each test has a negative control: the checker is run on a small tree that breaks the rule."""

import ast
import textwrap
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "skinfit"

#: The layers from the bottom up: a module may import from its own layer and those before it.
LAYERS = ("errors", "physics", "io", "posterior", "inference", "results", "analysis", "plots", "report", "apps")
MAX_LINES = 600


def modules(root):
    """{dotted module name: path} of every module under ``root`` (a package folder)."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


def imports(name, path):
    """(line, imported module, imported names) of every import of the package's own modules in
    a module, wherever it stands; relative imports resolved."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    top = name.split(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name, ()) for a in node.names if a.name.split(".")[0] == top]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] == top:
                found.append((node.lineno, target, tuple(a.name for a in node.names)))
    return found


def layer(name):
    parts = name.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in LAYERS else None


def upward_imports(root):
    """'module:line imports target' for each import of a higher layer than the importer's."""
    bad = []
    mods = modules(root)
    for name, path in mods.items():
        mine = layer(name)
        if mine is None:
            continue
        for line, target, names in imports(name, path):
            targets = [target] + [f"{target}.{n}" for n in names if f"{target}.{n}" in mods]
            for t in targets:
                theirs = layer(t)
                if theirs is not None and LAYERS.index(theirs) > LAYERS.index(mine):
                    bad.append(f"{name}:{line} imports {t}")
    return bad


def cycles(root):
    """Strongly connected groups of modules (over every import, function-level ones too)."""
    mods = modules(root)
    graph = {name: set() for name in mods}
    for name, path in mods.items():
        for _, target, names in imports(name, path):
            for t in [target] + [f"{target}.{n}" for n in names]:
                if t in mods and t != name and not name.startswith(t + "."):  # a package's own __init__
                    graph[name].add(t)
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):  # Tarjan's algorithm
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                out.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def private_imports(root):
    """'module:line imports _name from other' for a private name taken from another module."""
    mods = modules(root)
    bad = []
    for name, path in mods.items():
        for line, target, names in imports(name, path):
            for n in names:
                if n.startswith("_") and not n.startswith("__") and f"{target}.{n}" not in mods and target != name:
                    bad.append(f"{name}:{line} imports {n} from {target}")
    return bad


def long_modules(root):
    return [f"{p.relative_to(root.parent)}: {n} lines" for p in modules(root).values()
            if (n := len(p.read_text().splitlines())) > MAX_LINES]


def test_each_layer_imports_only_the_layers_below_it():
    assert upward_imports(PACKAGE) == []


def test_no_import_cycles():
    assert cycles(PACKAGE) == []


def test_no_private_name_imported_across_modules():
    assert private_imports(PACKAGE) == []


def test_no_module_over_600_lines():
    assert long_modules(PACKAGE) == []


@pytest.fixture
def broken(tmp_path):
    """A package that breaks each rule once."""
    files = {
        "__init__.py": "",
        "errors.py": "",
        "io/__init__.py": "",
        "io/data.py": "def load():\n    from pkg.report.html import write  # upward, inside a function\n",
        "report/__init__.py": "",
        "report/html.py": "from ..errors import _private\nfrom . import other\n",
        "report/other.py": "from pkg.report import html\n" + "x = 1\n" * 601,
    }
    for rel, text in files.items():
        path = tmp_path / "pkg" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))
    return tmp_path / "pkg"


def test_negative_controls_each_rule_fires(broken):
    assert upward_imports(broken) == ["pkg.io.data:2 imports pkg.report.html"]
    assert cycles(broken) == [["pkg.report.html", "pkg.report.other"]]
    assert private_imports(broken) == ["pkg.report.html:1 imports _private from pkg.errors"]
    assert long_modules(broken) == ["pkg/report/other.py: 602 lines"]
