"""docs/parameters.md is what the nodes declare: `tools/gen_parameters.py --check` builds each node and compares."""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import REPO

pytestmark = pytest.mark.ros  # builds every node under rclpy (on a private domain)


def test_parameters_page_is_up_to_date():
    result = subprocess.run([sys.executable, str(REPO / "tools" / "gen_parameters.py"), "--check"],
                            capture_output=True, text=True, timeout=180, cwd=REPO)
    assert result.returncode == 0, result.stderr[-2000:]
