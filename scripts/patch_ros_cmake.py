"""Point the ROS wheels' exported Python-generator CMake targets at this interpreter.

The ros-jazzy-* wheels were built in a manylinux container and their
``export_*__rosidl_generator_pyExport.cmake`` files name that container's
Python and numpy include directories, which do not exist here; CMake then
refuses to configure any interface package. Rewriting the two paths to this
venv's own include directories is the one fix needed (see ros-from-pypi.md).
"""

from __future__ import annotations

import re
import sys
import sysconfig
from pathlib import Path

import numpy

CONTAINER_PYTHON_INCLUDE = re.compile(r"/opt/python/cp3\d+-cp3\d+/include/python3\.\d+")
CONTAINER_NUMPY_INCLUDE = re.compile(
    r"/opt/python/cp3\d+-cp3\d+/lib/python3\.\d+/site-packages/numpy/(?:_core|core)/include")


def patch(prefix: Path) -> int:
    """Rewrite every export file under ``prefix/share``; return how many changed."""
    python_include = sysconfig.get_paths()["include"]
    numpy_include = numpy.get_include()
    changed = 0
    for path in prefix.glob("share/*/cmake/export_*__rosidl_generator_pyExport.cmake"):
        text = path.read_text()
        new = CONTAINER_NUMPY_INCLUDE.sub(numpy_include, text)
        new = CONTAINER_PYTHON_INCLUDE.sub(python_include, new)
        if new != text:
            path.write_text(new)
            changed += 1
    return changed


if __name__ == "__main__":
    count = patch(Path(sys.prefix))
    print(f"patched {count} ROS CMake export file(s) in {sys.prefix}")
