"""Argument types shared by woody sweep, run and calibrate: a bad value stops the command with one line."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from woody_tools.arguments import LINE_SPEEDS, POSITIVE_NUMBER, POSITIVE_NUMBERS, STIFFNESSES, YAW_SPREAD, add_yaw_sd


def _refused(parse, text: str) -> str:
    with pytest.raises(argparse.ArgumentTypeError) as refusal:
        parse(text)
    return str(refusal.value)


def test_lists_take_comma_separated_numbers_that_pass_their_check():
    assert STIFFNESSES("0, 20,100,") == [0.0, 20.0, 100.0]
    assert LINE_SPEEDS("100,130") == [100.0, 130.0] and POSITIVE_NUMBERS("0.1") == [0.1]
    assert _refused(STIFFNESSES, "0,-5") == "every k must be a finite number >= 0, got -5"
    assert _refused(STIFFNESSES, "inf") == "every k must be a finite number >= 0, got inf"
    assert _refused(LINE_SPEEDS, "100,401") == "every speed must be within 1..400 FPM, got 401"
    assert _refused(POSITIVE_NUMBERS, "0") == "every value must be a positive number, got 0"
    assert _refused(STIFFNESSES, "1,x") == "expected a number, got 'x'"
    assert _refused(STIFFNESSES, " , ") == "expected at least one number"


def test_single_numbers_pass_their_check():
    assert POSITIVE_NUMBER("20") == 20.0 and YAW_SPREAD("0") == 0.0 and YAW_SPREAD("45") == 45.0
    for bad in ("0", "-1", "nan", "inf"):
        assert "positive" in _refused(POSITIVE_NUMBER, bad)
    for bad in ("-1", "45.5", "nan", "inf"):
        assert _refused(YAW_SPREAD, bad) == f"must be within 0..45 degrees, got {bad}"
    assert _refused(YAW_SPREAD, "ten") == "expected a number, got 'ten'"


def test_the_yaw_option_defaults_to_straight_fillets_and_names_its_scope():
    parser = argparse.ArgumentParser()
    add_yaw_sd(parser, "here only")
    assert parser.parse_args([]).yaw_sd == 0.0 and parser.parse_args(["--yaw-sd", "7.5"]).yaw_sd == 7.5
    assert "here only" in parser.format_help()


def _woody(*args: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-c", "import sys; from woody_tools.cli import main; sys.exit(main(sys.argv[1:]))", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("args, line", [
    (("sweep", "--yaw-sd", "-5"), "argument --yaw-sd: must be within 0..45 degrees, got -5"),
    (("run", "--yaw-sd", "-5"), "woody run: --yaw-sd must be within 0..45 deg, got -5"),  # a line_sim placement option
    (("calibrate", "--yaw-sd", "-5"), "argument --yaw-sd: must be within 0..45 degrees, got -5"),
    (("sweep", "--k", "0,-5"), "argument --k: every k must be a finite number >= 0, got -5"),
    (("sweep", "--speeds", "0"), "argument --speeds: every speed must be within 1..400 FPM, got 0"),
    (("sweep", "--mass", "nan"), "argument --mass: must be a positive number, got nan"),
    (("calibrate", "--masses", "10,0"), "argument --masses: every value must be a positive number, got 0"),
    (("calibrate", "--meshes", "/no/such/meshes", "--skip-physics", "--dry-run", "--jobs", "1"),
     "woody calibrate: mesh spec '/no/such/meshes': not 'builtin', 'generated:N[:SEED]', a folder or a mesh file"),
    (("calibrate", "--top-camera", "fisheye", "--skip-physics", "--dry-run", "--jobs", "1"),
     "woody calibrate: --top-camera: unknown top camera preset 'fisheye'; known: default, paper, or a camera "
     "description file (*.yaml)"),
    (("calibrate", "--lanes", "7"), "argument --lanes: invalid choice: 7 (choose from 1, 2, 3, 4, 5, 6)"),
    (("calibrate", "--loo", "--meshes", "/no/such/meshes", "--jobs", "1"),
     "woody calibrate: mesh spec '/no/such/meshes': not 'builtin', 'generated:N[:SEED]', a folder or a mesh file"),
])
def test_every_command_refuses_a_bad_value_with_one_line_and_writes_nothing(args, line, tmp_path):
    done = _woody(*args, "--out", str(tmp_path / "out"))
    assert done.returncode == 2 and done.stderr.strip().splitlines()[-1].endswith(line)
    assert "Traceback" not in done.stderr and not (tmp_path / "out").exists()
