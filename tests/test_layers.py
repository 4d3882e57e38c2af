"""The one-way house: every import inside pinmsk points down the layers, and none closes a cycle.

Read from the source (module-level and function-level imports alike), so a deferred
import cannot hide a cycle.  The layers are those of docs/development.md, "Repository layout".
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


def _modules() -> dict[str, Path]:
    out = {}
    for p in PKG.rglob("*.py"):
        parts = list(p.relative_to(PKG).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


MODULES = _modules()


def layer(module: str) -> int:
    parts = module.split(".")
    for k in range(len(parts), 0, -1):
        key = ".".join(parts[:k])
        if key in LAYERS:
            return LAYERS[key]
    raise AssertionError(f"pinmsk.{module} has no layer in tests/test_layers.py: add it (and to docs/development.md)")


def _imports(module: str, path: Path) -> list[tuple[int, str]]:
    """(line, imported pinmsk module) for every import statement of ``module``."""
    is_pkg = path.name == "__init__.py"
    base = module.split(".") if module else []
    if not is_pkg:
        base = base[:-1]
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = base[: len(base) - (node.level - 1)] if node.level > 1 else base
                target = ".".join(anchor + ([node.module] if node.module else []))
            elif (node.module or "").startswith("pinmsk"):
                target = node.module[len("pinmsk"):].lstrip(".")
            else:
                continue
            for alias in node.names:          # `from . import x` imports the module x
                sub = f"{target}.{alias.name}" if target else alias.name
                out.append((node.lineno, sub if sub in MODULES else target))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("pinmsk."):
                    out.append((node.lineno, alias.name[len("pinmsk."):]))
    return sorted({(line, t) for line, t in out if t in MODULES and t != module})


GRAPH = {m: _imports(m, p) for m, p in MODULES.items() if m}   # the package __init__ only re-exports


def test_every_module_has_a_layer():
    for m in GRAPH:
        layer(m)


def test_imports_point_down_the_layers():
    wrong = []
    for m, edges in GRAPH.items():
        for line, t in edges:
            if t and layer(t) > layer(m):
                wrong.append(f"pinmsk/{MODULES[m].relative_to(PKG)}:{line}: {m} (layer {layer(m)}) imports "
                             f"{t} (layer {layer(t)})")
    assert not wrong, "imports against the flow:\n" + "\n".join(wrong)


def test_no_import_cycles():
    graph = {m: {t for _, t in e if t} for m, e in GRAPH.items()}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for t in sorted(graph.get(m, ())):
            if state.get(t) == 1:
                raise AssertionError("import cycle: " + " -> ".join(stack[stack.index(t):] + [t]))
            if t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)


def test_the_checks_see_a_cycle_and_a_wrong_way_import(tmp_path):
    """The detector itself: a deferred import inside a function is found like a top-level one."""
    src = "def f():\n    from ..presentation import plots\n    return plots\n"
    p = tmp_path / "x.py"
    p.write_text(src)
    MODULES["solvers.x"] = p
    try:
        edges = _imports("solvers.x", p)
        assert edges == [(2, "presentation.plots")]
        assert layer("presentation.plots") > layer("solvers.x")
    finally:
        del MODULES["solvers.x"]


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
