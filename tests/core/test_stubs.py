"""The shipped type stub names every public object of the compiled core (scripts/stubgen.sh)."""
import ast
from pathlib import Path

import cdam_core
from cdam_core import _core


def test_stub_lists_every_public_name():
    stub = Path(cdam_core.__file__).with_name("_core.pyi")
    tree = ast.parse(stub.read_text())
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    public = {n for n in dir(_core) if not n.startswith("_")}
    missing = public - names
    assert not missing, f"_core.pyi lacks {sorted(missing)}: run scripts/stubgen.sh"


def test_lazy_public_api_resolves():
    for name in cdam_core.__all__:
        assert getattr(cdam_core, name) is not None
