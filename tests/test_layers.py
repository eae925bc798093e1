"""The layers point one way: the runtime never imports the lab, ``alcn_cv`` never names ``pose``
or ``calib``, and no files or subpackages import each other.

Imports are read with :mod:`ast` from every file (module level and inside functions; the
``if TYPE_CHECKING:`` blocks, for annotations only, are skipped).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("alcn_cv", "pose", "calib")

#: What an OpenCV app imports: the apply() contract and the methods, the Gaussian mixture, the
#: Normalizer networks and runtimes, the weight file, io, errors, the command line and
#: ``alcn normalize`` (files, or folders for every file in them).
RUNTIME = (
    "alcn_cv/__init__.py",
    "alcn_cv/checks.py",
    "alcn_cv/cli.py",
    "alcn_cv/errors.py",
    "alcn_cv/extras.py",
    "alcn_cv/io.py",
    "alcn_cv/weight_file.py",
    "alcn_cv/runtime.py",
    "alcn_cv/nn.py",
    "alcn_cv/enhance/",
    "alcn_cv/filters/",
    "alcn_cv/nets/__init__.py",
    "alcn_cv/nets/normalizer.py",
    "alcn_cv/nets/lite.py",
    "alcn_cv/nets/gain.py",
    "alcn_cv/nets/opencv_runtime.py",
    "alcn_cv/nets/device.py",
    "alcn_cv/commands/__init__.py",
    "alcn_cv/commands/normalize.py",
)


def _module_files() -> dict[str, Path]:
    """Every module of the packages, by dotted name (a package by its ``__init__.py``)."""
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


MODULES = _module_files()


def _is_runtime(module: str) -> bool:
    rel = MODULES[module].relative_to(ROOT).as_posix()
    return any(rel == entry or (entry.endswith("/") and rel.startswith(entry)) for entry in RUNTIME)


def _syntax_tree(path: Path) -> ast.Module:
    """The file's tree without the bodies of ``if TYPE_CHECKING:`` blocks."""
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            node.body = []
    return tree


def _imported_names(module: str) -> set[str]:
    """The absolute names ``module`` imports: ``from a.b import c`` gives ``a.b.c`` when that is a
    module of the packages, else ``a.b``."""
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    names = set()
    for node in ast.walk(_syntax_tree(path)):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parent + ([base] if base else []))
            for alias in node.names:
                names.add(f"{base}.{alias.name}" if f"{base}.{alias.name}" in MODULES else base)
    return names


IMPORTS = {module: _imported_names(module) for module in MODULES}


def _internal(names: set[str]) -> set[str]:
    """The modules of the packages among ``names`` (``a.b.f`` for a function ``f`` of ``a.b``)."""
    found = set()
    for name in names:
        while name and name not in MODULES:
            name = name.rpartition(".")[0]
        if name:
            found.add(name)
    return found


GRAPH = {module: _internal(names) - {module} for module, names in IMPORTS.items()}


@pytest.mark.parametrize("module", sorted(m for m in MODULES if _is_runtime(m)))
def test_runtime_imports_only_the_runtime(module):
    lab = sorted(m for m in GRAPH[module] if not _is_runtime(m))
    assert not lab, f"{module} (runtime) imports the lab: {lab}"


# A string that names a module of pose or calib ("pose.cli", "calib.register:main"). The bare
# word "pose" is also a kind of generated dataset (alcn_cv.data.pose), which is not the package.
_NAMES_POSE_OR_CALIB = re.compile(r"(?<![\w.])(pose|calib)\.[A-Za-z_]\w*|^calib$")


@pytest.mark.parametrize("module", sorted(m for m in MODULES if m.split(".")[0] == "alcn_cv"))
def test_alcn_cv_never_names_pose_or_calib(module):
    imported = sorted(n for n in IMPORTS[module] if n.split(".")[0] in ("pose", "calib"))
    assert not imported, f"{module} imports {imported}"
    strings = [
        node.value
        for node in ast.walk(ast.parse(MODULES[module].read_text()))
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and _NAMES_POSE_OR_CALIB.search(node.value)
    ]
    assert not strings, f"{module} names pose or calib in {strings}"


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for other in sorted(graph[node]):
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while not component or component[-1] != node:
                component.append(stack.pop())
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_no_import_cycle_between_files():
    assert not _cycles(GRAPH), "import cycles: " + "; ".join(" <-> ".join(c) for c in _cycles(GRAPH))


def test_no_two_subpackages_import_each_other():
    """A subpackage is a top-level package, or a module or subpackage directly under one
    (``alcn_cv.data``, ``alcn_cv.io``, ``pose.build``); a package may use its own parents."""

    def units(module: str) -> set[str]:
        parts = module.split(".")
        return {parts[0], ".".join(parts[:2])}

    uses = {(a, b) for m, targets in GRAPH.items() for t in targets for a in units(m) for b in units(t)}
    uses = {(a, b) for a, b in uses if not (a + ".").startswith(b + ".") and not (b + ".").startswith(a + ".")}
    mutual = sorted({tuple(sorted(pair)) for pair in uses if pair[::-1] in uses})
    assert not mutual, "subpackages importing each other: " + "; ".join(" <-> ".join(p) for p in mutual)


def test_the_reader_sees_every_kind_of_import(tmp_path):
    """Relative, function-level and ``from package import module`` imports are edges;
    ``if TYPE_CHECKING:`` imports are not."""
    assert "alcn_cv.enhance.registry" in GRAPH["alcn_cv.enhance.alcn"]  # from alcn_cv.enhance.registry import register
    assert "alcn_cv.nets.opencv_runtime" in GRAPH["alcn_cv.enhance.alcn"]  # inside a method
    assert "alcn_cv.enhance.lcn" in GRAPH["alcn_cv.enhance"]  # from alcn_cv.enhance import lcn
    assert "calib.board" in GRAPH["calib.camera"]  # from .board import BoardSpec
    path = tmp_path / "typed.py"
    path.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import torch\ndef f():\n    from . import x\n")
    tree = _syntax_tree(path)
    assert [type(n).__name__ for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))] == ["ImportFrom", "ImportFrom"]
