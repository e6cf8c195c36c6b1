"""The package's architecture: imports go one way, no cycles, small modules, private names stay private.

Parses every module of ``fmu_src/l1b2`` (no import is executed) and checks:

* each layer imports only the layers below it (:data:`ALLOWED`), at module
  level and inside functions alike;
* no import cycle between modules;
* no module over 800 lines and no function over 120 lines;
* no private name (``_x``) of one module used from another;
* only ``workflows.py`` and ``cli.py`` (and the result objects' ``save``
  methods) open files for writing: no ``open(..., "w")``/``write_text`` in the
  algorithm layers.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "fmu_src" / "l1b2"

#: layer -> the layers it may import (besides itself)
ALLOWED = {
    "errors": {"units"},  # DataFormatError names the unit of a data column (l1b2.units.COLUMN_UNITS)
    "units": set(),
    "physics": {"errors", "units"},
    "data": {"errors", "units", "physics"},
    "predictor": {"errors", "units", "physics"},
    "cosim": {"errors", "units", "physics", "predictor"},
    "fmi": {"errors", "units", "physics", "predictor", "cosim"},
    "ident": {"errors", "units", "physics", "predictor", "data"},
    # closeloop -> cluster: its cross-validated refits are tasks of the parallel engine
    "closeloop": {"errors", "units", "physics", "predictor", "data", "ident", "cluster"},
    "cluster": {"errors", "units"},  # the parallel engine (Dask) under the rig, the sweeps and the closed loop
    "rig": {"errors", "units", "physics", "predictor", "cosim", "fmi", "data", "cluster"},
    "sweep": {"errors", "units", "physics", "predictor", "cosim", "fmi", "data", "rig", "cluster"},
    # multi-seed studies: rig data in memory, identified and closed-loop seed by seed on the parallel engine
    "study": {"errors", "units", "physics", "predictor", "cosim", "fmi", "data", "ident", "closeloop", "rig",
              "cluster"},
    "workflows": {"errors", "units", "physics", "predictor", "cosim", "fmi", "data", "ident", "closeloop", "rig",
                  "cluster", "sweep", "study", "__init__"},
    "cli": {"errors", "units", "physics", "predictor", "cosim", "fmi", "data", "ident", "closeloop", "rig",
            "cluster", "sweep", "study", "workflows", "console", "__init__"},
    "console": set(),  # the command line's terminal output (progress bar, warnings)
    "__init__": set(),
    "jsonio": set(),
}
#: the package's version lives in ``l1b2/__init__.py``, the one JSON writer of every report in
#: ``l1b2/jsonio.py``; any layer may use them
ALWAYS = {"__init__", "jsonio"}


def _modules() -> dict[str, Path]:
    out = {}
    for py in sorted(PKG.rglob("*.py")):
        rel = py.relative_to(PKG).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__" and len(parts) > 1:
            parts = parts[:-1]
        out[".".join(parts)] = py
    return out


MODULES = _modules()


def _layer(mod: str) -> str:
    return mod.split(".")[0]


def _imports(mod: str, path: Path) -> list[tuple[str, int]]:
    """Modules of ours imported by ``mod`` (dotted, without ``l1b2.``), with line numbers."""
    tree = ast.parse(path.read_text(), str(path))
    is_pkg = path.name == "__init__.py"
    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
    if mod == "__init__":
        base = []
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = base[: len(base) - (node.level - 1)] if node.level > 1 else base
                target = anchor + (node.module.split(".") if node.module else [])
            elif node.module and (node.module == "l1b2" or node.module.startswith("l1b2.")):
                target = node.module.split(".")[1:]
            else:
                continue
            names = [a.name for a in node.names]
            for name in names:
                dotted = ".".join(target + [name])
                found.append((dotted if dotted in MODULES else ".".join(target) or "__init__", node.lineno))
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name == "l1b2" or a.name.startswith("l1b2."):
                    found.append((".".join(a.name.split(".")[1:]) or "__init__", node.lineno))
    return found


def test_every_module_is_in_a_known_layer():
    unknown = sorted({_layer(m) for m in MODULES} - set(ALLOWED))
    assert not unknown, f"modules outside the declared layers: {unknown}"


def test_imports_go_one_way():
    bad = []
    for mod, path in MODULES.items():
        layer = _layer(mod)
        for target, line in _imports(mod, path):
            tl = _layer(target)
            if tl != layer and tl not in ALLOWED[layer] | ALWAYS:
                bad.append(f"{path.relative_to(PKG)}:{line}: {layer} imports {target}")
    assert not bad, "imports against the layering:\n" + "\n".join(bad)


def test_no_import_cycles():
    graph = {m: {t for t, _ in _imports(m, p) if t in MODULES and t != m} for m, p in MODULES.items()}
    # a package __init__ importing its own submodules is not a cycle of the code
    state: dict[str, int] = {}
    cycles = []

    def visit(node, stack):
        state[node] = 1
        stack.append(node)
        for nxt in graph[node]:
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt, stack)
        stack.pop()
        state[node] = 2

    for m in graph:
        if m not in state:
            visit(m, [])
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


@pytest.mark.parametrize("mod", sorted(MODULES))
def test_module_and_function_sizes(mod):
    path = MODULES[mod]
    text = path.read_text()
    assert len(text.splitlines()) <= 800, f"{path.relative_to(PKG)} has {len(text.splitlines())} lines (max 800)"
    long = [f"{n.name} ({n.end_lineno - n.lineno + 1} lines)" for n in ast.walk(ast.parse(text))
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.end_lineno - n.lineno + 1 > 120]
    assert not long, f"{path.relative_to(PKG)}: functions over 120 lines: {long}"


def test_no_private_name_crosses_modules():
    bad = []
    for mod, path in MODULES.items():
        tree = ast.parse(path.read_text())
        aliases = {}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.level or (node.module or "").startswith("l1b2")):
                for a in node.names:
                    if a.name.startswith("_") and not a.name.startswith("__"):
                        bad.append(f"{path.relative_to(PKG)}:{node.lineno}: imports private {a.name}")
                    aliases[a.asname or a.name] = a.name
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases and node.attr.startswith("_")
                    and not node.attr.startswith("__")):
                bad.append(f"{path.relative_to(PKG)}:{node.lineno}: uses {node.value.id}.{node.attr}")
    assert not bad, "private names used across modules:\n" + "\n".join(bad)


def test_no_old_flat_module_paths_linger():
    old = {"params", "driver", "stator", "interface", "slider", "coupled", "blocks", "ssp", "fmi_base",
           "fmu_build", "fmu_runtime", "export", "derive", "identify", "residuals", "effects", "metrics",
           "plots"}
    lingering = sorted(p.stem for p in PKG.glob("*.py") if p.stem in old)
    assert not lingering, f"old flat modules still present: {lingering}"
