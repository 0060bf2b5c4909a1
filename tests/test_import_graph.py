"""The woody packages import each other one way: no import circle among src/'s modules, no private name borrowed.

The graph is built from the AST of every module under ``src/<package>/<package>/``:
module-level and function-level imports alike, so a circle cannot hide behind
an import inside a function. A private name (``_x``) belongs to its module:
no other module imports it (``from m import _x``) or reaches for it (``m._x``).
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"


def modules(src: Path = SRC) -> dict[str, Path]:
    """Dotted module name -> file, for every Python module of every package under ``src``."""
    found = {}
    for package_dir in sorted(p for p in src.iterdir() if (p / p.name / "__init__.py").is_file()):
        root = package_dir / package_dir.name
        for path in sorted(root.rglob("*.py")):
            parts = list(path.relative_to(package_dir).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


def _absolute(module: str | None, level: int, importer: str, is_package: bool) -> str:
    """The absolute name of a (possibly relative) ``from`` import in ``importer``."""
    if not level:
        return module or ""
    base = importer.split(".")
    base = base[: len(base) - level + (1 if is_package else 0)]
    return ".".join(base + ([module] if module else []))


def imports(name: str, path: Path, known: dict[str, Path]) -> list[tuple[str, str | None, int]]:
    """(imported module, name taken from it or None, line) of every import of one module, at any depth."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(alias.name, None, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            source = _absolute(node.module, node.level, name, path.name == "__init__.py")
            for alias in node.names:
                child = f"{source}.{alias.name}"
                out.append((child, None, node.lineno) if child in known else (source, alias.name, node.lineno))
    return [(m, n, line) for m, n, line in out if m in known]


def import_graph(src: Path = SRC) -> dict[str, set[str]]:
    known = modules(src)
    return {name: {m for m, _, _ in imports(name, path, known) if m != name} for name, path in known.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def private_borrowings(src: Path = SRC) -> list[str]:
    """``module:line name`` of every private name one module takes from another woody module."""
    known = modules(src)
    found = []
    for name, path in known.items():
        bound: dict[str, str] = {}  # local name -> woody module it stands for
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name in known:
                        bound[alias.asname or alias.name] = alias.name
            elif isinstance(node, ast.ImportFrom):
                source = _absolute(node.module, node.level, name, path.name == "__init__.py")
                for alias in node.names:
                    if f"{source}.{alias.name}" in known:
                        bound[alias.asname or alias.name] = f"{source}.{alias.name}"
        for module, taken, line in imports(name, path, known):
            if taken and taken.startswith("_") and not taken.startswith("__") and module != name:
                found.append(f"{name}:{line} imports {module}.{taken}")
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in bound
                    and node.attr.startswith("_") and not node.attr.startswith("__")
                    and bound[node.value.id] != name):
                found.append(f"{name}:{node.lineno} uses {bound[node.value.id]}.{node.attr}")
    return found


def test_the_graph_sees_every_package_and_its_imports():
    graph = import_graph()
    assert {name.split(".")[0] for name in graph} >= {
        "woody_common", "woody_sim", "woody_vision", "woody_bag", "woody_experiments", "woody_tools"}
    assert "woody_experiments.experiment" in graph["woody_experiments.sweep"]
    assert "woody_bag.writer" in graph["woody_bag.recorder_node"]


def test_no_import_circle_in_src():
    assert cycles(import_graph()) == []


def test_no_private_name_is_imported_from_another_module():
    assert private_borrowings() == []


def test_the_checks_see_a_circle_and_a_private_import(tmp_path):
    package = tmp_path / "woody_demo" / "woody_demo"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("from woody_demo.b import _helper\n")
    (package / "b.py").write_text("def f():\n    from woody_demo import a\n    return a._x\n\n\n"
                                  "def _helper():\n    pass\n")
    assert cycles(import_graph(tmp_path)) == [["woody_demo.a", "woody_demo.b"]]
    assert private_borrowings(tmp_path) == ["woody_demo.a:1 imports woody_demo.b._helper",
                                            "woody_demo.b:3 uses woody_demo.a._x"]
