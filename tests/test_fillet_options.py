"""--yaw-sd, shared by woody sweep, run and calibrate: a bad spread stops the command with one line."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from woody_tools.fillet_options import add_yaw_sd, yaw_spread


def test_a_yaw_spread_is_degrees_within_zero_to_45():
    assert yaw_spread("0") == 0.0 and yaw_spread("13") == 13.0 and yaw_spread("45") == 45.0
    for bad in ("-1", "45.5", "nan", "inf", "ten"):
        with pytest.raises(argparse.ArgumentTypeError):
            yaw_spread(bad)


def test_the_option_defaults_to_straight_fillets_and_names_its_scope():
    parser = argparse.ArgumentParser()
    add_yaw_sd(parser, "here only")
    assert parser.parse_args([]).yaw_sd == 0.0 and parser.parse_args(["--yaw-sd", "7.5"]).yaw_sd == 7.5
    assert "here only" in parser.format_help()


@pytest.mark.parametrize("command", ["sweep", "run", "calibrate"])
def test_every_command_refuses_a_bad_spread_before_it_starts(command, tmp_path):
    cmd = [sys.executable, "-c", "import sys; from woody_tools.cli import main; sys.exit(main(sys.argv[1:]))",
           command, "--yaw-sd", "-5", "--out", str(tmp_path / "out")]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "--yaw-sd: must be within 0..45 degrees, got -5" in done.stderr
    assert not (tmp_path / "out").exists()
