"""The layering of roshan.kernels and roshan.env, read from the import statements."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2] / "roshan"
BASE = ("roshan.config", "roshan.maps", "roshan.runtime", "roshan.episode")
ALLOWED = {
    "kernels": BASE + ("roshan.kernels",),
    "env": BASE + ("roshan.kernels", "roshan.env", "roshan.algos.frozen"),
}


def roshan_imports(tree: ast.AST):
    """(module, node) of every import of a roshan module, however written."""
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("roshan"):
            for alias in node.names:
                yield f"{node.module}.{alias.name}", node
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("roshan"):
                    yield alias.name, node


def within(module: str, allowed: tuple[str, ...]) -> bool:
    return any(module == a or module.startswith(a + ".") for a in allowed)


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_packages_import_only_their_layer_and_below_at_module_level(package):
    for path in sorted((ROOT / package).glob("*.py")):
        tree = ast.parse(path.read_text())
        top_level = {id(n) for n in tree.body}
        for module, node in roshan_imports(tree):
            assert within(module, ALLOWED[package]), f"{path.name} imports {module}"
            assert id(node) in top_level, f"{path.name}:{node.lineno} imports {module} inside a function"
