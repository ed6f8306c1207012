"""The package follows the chain: a stage never imports a later one, no import cycle exists
(lazy imports inside functions count too), and the numpy twin neither serves nor is served.

The order is the one docs/DESIGN.md draws; the test reads the source files (ast), so it sees
imports inside functions that a runtime check would miss.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import cdam_core

STAGES = ("base", "record", "sim", "preprocess", "models", "identify", "evaluate", "residual",
          "report", "paper", "fleet", "firmware", "cli")
PKG = Path(cdam_core.__file__).resolve().parent


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PKG).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(["cdam_core", *parts])


def _modules() -> dict[str, Path]:
    # firmware_src/ is package data an installed wheel carries (the firmware sources and their
    # host scripts), not modules of the package
    return {_module_name(p): p for p in PKG.rglob("*.py")
            if "firmware_src" not in p.relative_to(PKG).parts}


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """Every cdam_core module ``name`` imports, at any depth of the file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    is_pkg = path.name == "__init__.py"
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.startswith("cdam_core"))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name if is_pkg else name.rsplit(".", 1)[0]
                for _ in range(node.level - 1):
                    base = base.rsplit(".", 1)[0]
                mod = base + ("." + node.module if node.module else "")
            else:
                mod = node.module or ""
            if not mod.startswith("cdam_core"):
                continue
            for a in node.names:
                sub = f"{mod}.{a.name}"
                out.add(sub if sub in known else mod)
    out.discard(name)
    return out


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    known = set(mods) | {"cdam_core._core"}
    return {m: _imports(m, p, known) for m, p in mods.items()}


def _stage(mod: str):
    parts = mod.split(".")
    if len(parts) < 2:
        return None                      # the package facade (lazy public names)
    top = parts[1]
    if top in ("_core", "__main__", "__init__"):
        return None
    return top


def test_every_subpackage_is_a_known_stage():
    tops = {_stage(m) for m in _graph()} - {None}
    assert tops <= set(STAGES) | {"reference"}, tops - set(STAGES)


def test_no_stage_imports_a_later_stage():
    bad = []
    for mod, deps in _graph().items():
        s = _stage(mod)
        if s is None or s == "reference":
            continue
        for d in deps:
            t = _stage(d)
            if t is None or t == "reference":
                continue
            if STAGES.index(t) > STAGES.index(s):
                bad.append(f"{mod} ({s}) imports {d} ({t})")
    assert not bad, "\n".join(sorted(bad))


def test_reference_neither_serves_nor_is_served():
    bad = []
    for mod, deps in _graph().items():
        s = _stage(mod)
        for d in deps:
            t = _stage(d)
            if s == "reference" and t != "reference":
                bad.append(f"the twin {mod} imports {d}")
            if s != "reference" and t == "reference":
                bad.append(f"{mod} imports the twin {d}")
    assert not bad, "\n".join(sorted(bad))


def test_no_import_cycle():
    graph = _graph()
    state: dict[str, int] = {}
    cycles = []

    def visit(m, stack):
        state[m] = 1
        stack.append(m)
        for d in sorted(graph.get(m, ())):
            if d not in graph:
                continue
            if state.get(d) == 1:
                cycles.append(stack[stack.index(d):] + [d])
            elif d not in state:
                visit(d, stack)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [])
    assert not cycles, "\n".join(" -> ".join(c) for c in cycles)


def test_reference_imports_with_star():
    ns: dict = {}
    exec("from cdam_core.reference import *", ns)
    import cdam_core.reference as ref
    for name in ref.__all__:
        assert name in ns


def test_the_test_sees_a_violation(tmp_path):
    """The walker itself: a later-stage import inside a function is found."""
    p = PKG / "base" / "checks.py"
    tree_mods = _imports("cdam_core.base.checks", p, set(_modules()))
    assert all(_stage(d) in (None, "base") for d in tree_mods)
    fake = tmp_path / "x.py"
    fake.write_text("def f():\n    from cdam_core.cli.main import main\n")
    deps = _imports("cdam_core.base.x", fake, set(_modules()))
    assert "cdam_core.cli.main" in deps


@pytest.mark.parametrize("stage", STAGES)
def test_stage_imports(stage):
    """Each stage package imports on its own (no hidden order dependence)."""
    import importlib
    import subprocess
    import sys
    r = subprocess.run([sys.executable, "-c", f"import cdam_core.{stage}"], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    importlib.import_module(f"cdam_core.{stage}")
