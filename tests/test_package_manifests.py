"""Each package.xml declares the ROS packages its Python imports, and the vision nodes run without the simulator."""

import ast
import re
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGES = ["woody_common", "woody_sim", "woody_vision", "woody_bag", "woody_experiments", "woody_tools"]


def ros_imports(package: str) -> set[str]:
    """Top-level modules the package imports that are ROS packages (rclpy, *_msgs, *_interfaces, woody_*)."""
    found = set()
    for path in (SRC / package / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module] if isinstance(node, ast.ImportFrom) and node.module and not node.level else [])
            found |= {n.split(".")[0] for n in names}
    return {m for m in found if m == "rclpy" or m.endswith(("_msgs", "_interfaces")) or m.startswith("woody_")} - {
        package}


@pytest.mark.parametrize("package", PACKAGES)
def test_package_xml_declares_every_imported_ros_package(package):
    declared = set(re.findall(r"<(?:exec_)?depend>([^<]+)</", (SRC / package / "package.xml").read_text()))
    assert ros_imports(package) - declared == set()


def test_vision_does_not_import_the_simulator():
    assert "woody_sim" not in ros_imports("woody_vision")
