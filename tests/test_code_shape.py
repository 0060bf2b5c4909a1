"""The code stays short-functioned: no function over MAX_LINES lines outside the vectorised kernels named here."""

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
MAX_LINES = 60
KERNELS: set[str] = set()
"""``path::function`` of vectorised kernels (numba / numpy rasterisers) allowed to be longer; none is today."""


def long_functions(root: Path = REPO) -> list[str]:
    found = []
    for folder in ("src", "tests", "tools", "scripts"):
        for path in sorted((root / folder).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    lines = node.end_lineno - node.lineno + 1
                    name = f"{path.relative_to(root)}::{node.name}"
                    if lines > MAX_LINES and name not in KERNELS:
                        found.append(f"{name} ({lines} lines)")
    return found


def test_no_function_is_over_60_lines():
    assert long_functions() == []


def test_the_check_sees_a_long_function(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_LINES))
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "long.py").write_text(f"def too_long():\n{body}\n")
    assert long_functions(tmp_path) == ["src/long.py::too_long (61 lines)"]
