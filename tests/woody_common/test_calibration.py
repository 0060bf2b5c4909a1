"""woody_common.calibration: which file (option, environment, installed), reading, writing, node defaults."""

from __future__ import annotations

import dataclasses

import pytest

from woody_common.calibration import (
    ENV_VAR,
    installed_calibration,
    load_calibration,
    node_defaults,
    resolve_calibration,
    resolved_calibration,
    write_calibration,
)

GRADER = ("threshold", "line_threshold", "severe_threshold", "fitted_range")


@pytest.fixture
def no_env(monkeypatch):
    monkeypatch.delenv(ENV_VAR, raising=False)


def test_the_installed_calibration_is_package_data_and_a_calibration(no_env):
    path = installed_calibration()
    assert path.is_file()
    assert path.parent.name == "config" and path.parent.parent.name == "woody_common"
    assert resolve_calibration() == path
    assert resolved_calibration() == load_calibration(path)


def test_option_before_environment_before_installed(tmp_path, monkeypatch):
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "env.yaml"))
    assert resolve_calibration(tmp_path / "option.yaml") == tmp_path / "option.yaml"
    assert resolve_calibration(None) == tmp_path / "env.yaml"
    monkeypatch.setenv(ENV_VAR, "")
    assert resolve_calibration(None) == installed_calibration()


def test_a_missing_or_foreign_file_is_one_clear_error(tmp_path):
    with pytest.raises(ValueError, match="cannot read the calibration"):
        load_calibration(tmp_path / "none.yaml")
    (tmp_path / "other.yaml").write_text("/**/line_sim:\n  ros__parameters:\n    mass: 1.0\n")
    with pytest.raises(ValueError, match="not a woody calibration file"):
        resolved_calibration(tmp_path / "other.yaml")


def test_write_then_read_round_trips_and_follows_a_link(tmp_path, no_env):
    calibration = dataclasses.replace(resolved_calibration(), phi_threshold=9.5, provenance={"command": "test"})
    target = tmp_path / "real.yaml"
    write_calibration(calibration, target)
    link = tmp_path / "link.yaml"
    link.symlink_to(target)
    moved = dataclasses.replace(calibration, total_mass_kg=12.0)
    assert write_calibration(moved, link) == target
    assert link.is_symlink()
    assert load_calibration(link) == moved and load_calibration(link).provenance == {"command": "test"}


def test_node_defaults_read_no_file_when_the_params_file_gives_them(tmp_path, monkeypatch):
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "absent.yaml"))  # any read would raise
    given = {"threshold": 11, "line_threshold": [7, 0, 0, 0, 0],
             "severe_threshold": [5.0, 0, 0, 0, 0], "fitted_range": [0.4, 0.8, 40, 0.1, 0.3], "lanes": 3}
    defaults = node_defaults("grader", given)
    assert set(defaults) == set(GRADER)
    assert defaults["threshold"] == 11.0 and isinstance(defaults["threshold"], float)
    assert defaults["line_threshold"] == [7.0, 0.0, 0.0, 0.0, 0.0]
    with pytest.raises(ValueError, match="absent.yaml"):
        node_defaults("grader", {"threshold": 11.0})


def test_node_defaults_otherwise_come_from_the_resolved_calibration(no_env):
    calibration = resolved_calibration()
    assert node_defaults("line_sim") == {"mass": calibration.total_mass_kg, "damping": calibration.hinge_damping,
                                         "friction_static": calibration.friction_static,
                                         "friction_dynamic": calibration.friction_dynamic}
    assert node_defaults("grader")["line_threshold"] == list(calibration.line_threshold)



def test_the_fitted_range_is_five_finite_numbers(no_env):
    calibration = resolved_calibration()
    assert len(calibration.fitted_range) == 5
    with pytest.raises(ValueError, match="fitted_range must be 5 finite numbers"):
        dataclasses.replace(calibration, fitted_range=(0.4, 0.8, 40.0))
    with pytest.raises(ValueError, match="fitted_range"):
        dataclasses.replace(calibration, fitted_range=(0.4, float("nan"), 40.0, 0.1, 0.3))
