"""The one-way house: every import inside pinmsk points down the layers, and none closes a cycle.

Read from the source (module-level and function-level imports alike), so a deferred
import cannot hide a cycle.  An import is any of:

* ``import pinmsk.x`` / ``from pinmsk.x import y`` / ``from .x import y`` (``y`` a submodule, or a
  name of ``x``'s lazy table: then the submodule that defines it);
* attribute access after an import: ``import pinmsk`` then ``pinmsk.presentation.plots.f``;
* ``importlib.import_module("pinmsk.x")`` (or ``(".x", __name__)``) with a literal name;
* a lazy table: the name -> submodule dict handed to :func:`pinmsk._lazy.lazy_attributes`, and any
  other dict whose values all name modules of the package (``"pinmsk.x"``, or a submodule of the
  module's own package in a module that imports by a computed name).

The layers are those of docs/development.md, "Repository layout".
"""
from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "pinmsk"

#: Module (dotted, without ``pinmsk.``) or package prefix -> layer; the longest prefix wins.
LAYERS = {
    "errors": 0, "_lazy": 0, "_blas": 0, "stats": 0, "backend": 0,
    "signals.sampling": 1, "signals.filtering": 1, "signals.iir": 1, "signals.bspline": 1,
    "trial": 2,
    "signals": 3,
    "io": 4,
    "components": 5, "fitting": 5,
    "muscles": 6, "effects": 6, "contact": 6, "skeleton": 6, "actuators": 6,
    "kinematics": 7, "grf": 7, "residuals": 7, "opensim": 7,
    "builtin_models": 8, "model": 8,
    "markers": 9, "ik": 9, "dynamics": 9, "energy": 9, "contact.identify": 9, "contact.synthetic": 9,
    "solvers": 11,
    "diagnose": 12,
    "presentation": 13,
    "pipeline": 14, "demo": 14, "gait_validation": 14, "tools": 14, "subjects": 14,
    "presentation.cli": 15, "__main__": 15,
}

#: Known edges against the flow, each kept on purpose until the code moves; printed by
#: ``test_imports_point_down_the_layers`` and checked to be still needed (a stale entry fails).
#: (importing module, imported module) -> why it is allowed for now.
ALLOWED_UPWARD = {
    # pinmsk.contact re-exports its identification names (ContactFit, load_foot2d, ...) lazily, so
    # ``from pinmsk.contact import ContactFit`` keeps working; the identification itself builds models
    # (layer 9) and is imported only when one of those names is first used.  Moving it out of the
    # package (a layer-9 package of its own) changes the public import path.
    ("contact", "contact.identify"): "lazy re-export of the contact identification (public API)",
    ("contact", "contact.synthetic"): "lazy re-export of synthetic_foot_trial (public API)",
}


def _modules(root: Path) -> dict[str, Path]:
    out = {}
    for p in root.rglob("*.py"):
        parts = list(p.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def layer(module: str) -> int:
    parts = module.split(".")
    for k in range(len(parts), 0, -1):
        key = ".".join(parts[:k])
        if key in LAYERS:
            return LAYERS[key]
    raise AssertionError(f"pinmsk.{module} has no layer in tests/test_layers.py: add it (and to docs/development.md)")


def _package_of(module: str, path: Path) -> list[str]:
    base = module.split(".") if module else []
    return base if path.name == "__init__.py" else base[:-1]


def _str(node) -> str | None:
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else None


def _dict_tables(module: str, path: Path, nodes: list, modules) -> list[tuple[int, dict[str, str]]]:
    """``(line, {name: module})`` of each lazy table of ``module`` (see the module docstring)."""
    pkg = ".".join(_package_of(module, path))
    dicts: dict[str, ast.Dict] = {}
    for node in nodes:
        if isinstance(node, (ast.Assign, ast.AnnAssign)) and isinstance(node.value, ast.Dict):
            for t in (node.targets if isinstance(node, ast.Assign) else [node.target]):
                if isinstance(t, ast.Name):
                    dicts[t.id] = node.value
    handed = set()              # dicts passed to lazy_attributes(package, TABLE, ...)
    computed = False            # import_module / __import__ with a name that is not a literal
    for node in nodes:
        if isinstance(node, ast.Call):
            fn = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", None)
            if fn == "lazy_attributes" and len(node.args) > 1 and isinstance(node.args[1], ast.Name):
                handed.add(node.args[1].id)
            if fn in ("import_module", "__import__") and node.args and _str(node.args[0]) is None:
                computed = True

    def resolve(value: str, relative: bool) -> str | None:
        if value.startswith("pinmsk."):
            return value[len("pinmsk."):] if value[len("pinmsk."):] in modules else None
        if relative:
            full = f"{pkg}.{value.lstrip('.')}" if pkg else value.lstrip(".")
            return full if full in modules else None
        return None

    out = []
    for name, d in dicts.items():
        values = [_str(v) for v in d.values]
        keys = [_str(k) if k is not None else None for k in d.keys]
        if not values or None in values or None in keys:
            continue
        relative = name in handed or computed
        resolved = [resolve(v, relative) for v in values]
        if None in resolved:
            continue
        out.append((d.lineno, dict(zip(keys, resolved))))
    return out


def scan(root: Path) -> tuple[dict[str, Path], dict[str, list[tuple[int, str]]]]:
    """``(modules, graph)`` of the package at ``root``: graph[module] = sorted (line, imported module)."""
    modules = _modules(root)
    kinds = (ast.Import, ast.ImportFrom, ast.Call, ast.Attribute, ast.Assign, ast.AnnAssign)
    trees = {m: [n for n in ast.walk(ast.parse(p.read_text())) if isinstance(n, kinds)]
             for m, p in modules.items()}     # the nodes read below: one walk of each file
    tables: dict[str, dict[str, str]] = {}        # package -> its lazy table (name -> module)
    lazy_edges: dict[str, list[tuple[int, str]]] = {}
    for m, p in modules.items():
        for line, table in _dict_tables(m, p, trees[m], modules):
            lazy_edges.setdefault(m, []).extend((line, t) for t in table.values())
            if p.name == "__init__.py":
                tables.setdefault(m, {}).update(table)

    def member(package: str, name: str) -> str:
        """The module ``package.name`` stands for: a submodule, a lazy name's module, or the package."""
        sub = f"{package}.{name}" if package else name
        if sub in modules:
            return sub
        return tables.get(package, {}).get(name, package)

    graph = {}
    for m, p in modules.items():
        base = _package_of(m, p)
        out = list(lazy_edges.get(m, ()))
        aliases: dict[str, str] = {}              # local name -> the pinmsk module it is bound to
        for node in trees[m]:
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    anchor = base[: len(base) - (node.level - 1)] if node.level > 1 else base
                    target = ".".join(anchor + ([node.module] if node.module else []))
                elif node.module == "pinmsk" or (node.module or "").startswith("pinmsk."):
                    target = node.module[len("pinmsk"):].lstrip(".")
                else:
                    continue
                for alias in node.names:          # `from . import x`: the module x, or x's lazy module
                    sub = f"{target}.{alias.name}" if target else alias.name
                    if sub in modules:
                        out.append((node.lineno, sub))
                        aliases[alias.asname or alias.name] = sub
                    else:                         # a name of target: target, and its module if lazy
                        out += [(node.lineno, target), (node.lineno, member(target, alias.name))]
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name == "pinmsk" or alias.name.startswith("pinmsk."):
                        target = alias.name[len("pinmsk"):].lstrip(".")
                        out.append((node.lineno, target))
                        if alias.asname:
                            aliases[alias.asname] = target
                        else:
                            aliases["pinmsk"] = ""
            elif isinstance(node, ast.Call):
                fn = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", None)
                name = _str(node.args[0]) if fn in ("import_module", "__import__") and node.args else None
                if name is None:
                    continue
                if name.startswith("."):
                    anchor = _str(node.args[1]) if len(node.args) > 1 else None
                    if anchor is None and len(node.args) > 1 and getattr(node.args[1], "id", "") in (
                            "__name__", "__package__"):
                        anchor = "pinmsk." + ".".join(base) if base else "pinmsk"
                    name = f"{anchor}{name}" if anchor else ""
                if name == "pinmsk" or name.startswith("pinmsk."):
                    out.append((node.lineno, name[len("pinmsk"):].lstrip(".")))
        for node in trees[m]:                     # attribute access on a bound module: pinmsk.a.b.c
            if not isinstance(node, ast.Attribute):
                continue
            chain, root_node = [], node
            while isinstance(root_node, ast.Attribute):
                chain.append(root_node.attr)
                root_node = root_node.value
            if not isinstance(root_node, ast.Name) or root_node.id not in aliases:
                continue
            cur = aliases[root_node.id]
            for attr in reversed(chain):
                nxt = member(cur, attr)
                if nxt == cur:                    # a plain attribute: the chain leaves the modules
                    break
                named = nxt != (f"{cur}.{attr}" if cur else attr)     # a lazy name: its module, then stop
                cur = nxt
                if named:
                    break
            out.append((node.lineno, cur))
        graph[m] = sorted({(line, t) for line, t in out if t in modules and t and t != m})
    return modules, graph


def wrong_way(modules, graph, allowed=()) -> list[str]:
    """The edges of ``graph`` that point up the layers (and are not in ``allowed``), as text."""
    wrong = []
    for m, edges in sorted(graph.items()):
        if not m:                                 # the package __init__ only re-exports
            continue
        for line, t in edges:
            if layer(t) > layer(m) and (m, t) not in allowed:
                wrong.append(f"pinmsk/{modules[m].relative_to(modules[''].parent)}:{line}: {m} (layer {layer(m)}) "
                             f"imports {t} (layer {layer(t)})")
    return wrong


def find_cycle(graph) -> list[str] | None:
    """One import cycle of ``graph`` (``[a, b, ..., a]``), or None."""
    adj = {m: {t for _, t in e} for m, e in graph.items()}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for t in sorted(adj.get(m, ())):
            if state.get(t) == 1:
                return stack[stack.index(t):] + [t]
            if t not in state:
                found = visit(t)
                if found:
                    return found
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(adj):
        if m not in state:
            found = visit(m)
            if found:
                return found
    return None


MODULES, _GRAPH = scan(PKG)
GRAPH = {m: e for m, e in _GRAPH.items() if m}     # the package __init__ only re-exports


def test_every_module_has_a_layer():
    for m in GRAPH:
        layer(m)


def test_imports_point_down_the_layers():
    print("edges against the flow allowed for now (tests/test_layers.py ALLOWED_UPWARD):")
    for (m, t), why in ALLOWED_UPWARD.items():
        print(f"  {m} (layer {layer(m)}) -> {t} (layer {layer(t)}): {why}")
    wrong = wrong_way(MODULES, GRAPH, ALLOWED_UPWARD)
    assert not wrong, "imports against the flow:\n" + "\n".join(wrong)
    edges = {(m, t) for m, e in GRAPH.items() for _, t in e}
    stale = [k for k in ALLOWED_UPWARD if k not in edges or layer(k[1]) <= layer(k[0])]
    assert not stale, f"ALLOWED_UPWARD entries no longer needed, remove them: {stale}"


def test_no_import_cycles():
    # an allowed upward edge is a lazy re-export, imported on first use: it is left out of the cycle check
    # only because it is listed (and printed) above
    graph = {m: [(line, t) for line, t in e if (m, t) not in ALLOWED_UPWARD] for m, e in GRAPH.items()}
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)


def test_the_checks_see_every_kind_of_wrong_way_import_and_a_cycle(tmp_path):
    """The detector itself, on a package built here: each kind of import in the module docstring is
    found, pointing up the layers, and a cycle closed through ``import_module`` is found."""
    root = tmp_path / "pinmsk"
    _write(root, {
        "__init__.py": "from ._lazy import lazy_attributes\n_LAZY = {'plot': 'presentation.plots'}\n"
                       "__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, ['plot'])\n",
        "_lazy.py": "def lazy_attributes(*a):\n    return None, None\n",
        "presentation/__init__.py": "",
        "presentation/plots.py": "def f():\n    return 1\n",
        "solvers/__init__.py": "",
        # attribute access after `import pinmsk`
        "solvers/attribute.py": "import pinmsk\n\n\ndef g():\n    return pinmsk.presentation.plots.f()\n",
        # a literal import_module
        "solvers/by_name.py": "import importlib\n\nplots = importlib.import_module('pinmsk.presentation.plots')\n",
        # a name of the root's lazy table
        "solvers/lazy_name.py": "from pinmsk import plot\n",
        # attribute access on the root reaching a lazy name
        "solvers/lazy_attribute.py": "import pinmsk as pm\n\nF = pm.plot\n",
        # a deferred relative import
        "solvers/deferred.py": "def f():\n    from ..presentation import plots\n    return plots\n",
        # harmless: attribute access that stays down, a stdlib import_module
        "solvers/fine.py": "import importlib\nimport pinmsk\n\nE = pinmsk.errors.X\nj = importlib.import_module('json')\n",
        "errors.py": "import importlib\n\nX = 1\nB = importlib.import_module('.backend', __package__)\n",
        "backend.py": "from .errors import X\n",
        # a package's lazy table pointing up to its own model-level submodule
        "contact/__init__.py": "from .._lazy import lazy_attributes\n_LAZY = {'Fit': 'identify'}\n"
                               "__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, ['Fit'])\n",
        "contact/identify.py": "class Fit:\n    pass\n",
        # a dict of module paths, imported by a computed name
        "tools/__init__.py": "import importlib\nRUNNERS = {'x': 'pinmsk.presentation.plots'}\n\n\n"
                             "def run(k):\n    return importlib.import_module(RUNNERS[k])\n",
    })
    modules, graph = scan(root)
    wrong = "\n".join(wrong_way(modules, graph))
    for m, line in [("solvers.attribute", 5), ("solvers.by_name", 3), ("solvers.lazy_name", 1),
                    ("solvers.lazy_attribute", 3), ("solvers.deferred", 2)]:
        assert f"{m.replace('.', '/')}.py:{line}: {m} (layer 11) imports presentation.plots (layer 13)" in wrong, m
    assert "contact/__init__.py:2: contact (layer 6) imports contact.identify (layer 9)" in wrong
    assert "solvers.fine" not in wrong and "tools" not in wrong      # tools (14) may import presentation (13)
    assert (2, "presentation.plots") in graph["tools"]
    assert "solvers/attribute.py:5: solvers.attribute (layer 11) imports presentation (layer 13)" in wrong
    assert (4, "errors") in graph["solvers.fine"] and len(wrong.splitlines()) == 7, wrong
    assert find_cycle(graph) == ["backend", "errors", "backend"]
    del graph["errors"]
    assert find_cycle(graph) is None


def test_every_subpackage_ships_in_the_wheel():
    """A package missing from pyproject's list installs from a checkout (-e) but not from a wheel."""
    import sys
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    listed = set(tomllib.loads((PKG.parent / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {"pinmsk" + ("." + ".".join(p.parent.relative_to(PKG).parts) if p.parent != PKG else "")
             for p in PKG.rglob("__init__.py")}
    assert found <= listed, f"add to pyproject.toml [tool.setuptools] packages: {sorted(found - listed)}"
