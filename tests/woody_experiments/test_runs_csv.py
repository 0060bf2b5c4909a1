"""woody_experiments.runs_csv: typed rows read back as written, atomic replacement, torn rows dropped."""

from __future__ import annotations

import math

import pytest

from woody_experiments import runs_csv, sweep
from woody_experiments.runs_csv import FILE_NAME, RUN_COLUMNS, RunsFile, read_runs

ROW = {"mesh": "m", "k": 0.0, "speed_fpm": 100.0, "lane": 0, "mass": 20.0, "phi": 1.5, "status": "scored",
       "blunt_first": 1, "rejected": 0, "leading_end": "narrow", "trace": [1, 2]}


def test_rows_read_back_typed(tmp_path):
    path = tmp_path / FILE_NAME
    RunsFile(path, [ROW, dict(ROW, lane=1, phi=math.nan, k=100.0)])
    assert path.read_text().splitlines()[0].split(",") == RUN_COLUMNS  # the trace is not a column
    first, second = read_runs(path)
    assert (first["mesh"], first["lane"], first["k"], first["phi"], first["blunt_first"]) == ("m", 0, 0.0, 1.5, 1.0)
    assert isinstance(first["lane"], int) and isinstance(first["speed_fpm"], float)
    assert math.isnan(first["nmdm"]) and first["reason"] == "" and first["leading_end"] == "narrow"
    assert math.isnan(second["phi"]) and second["k"] == 100.0
    RunsFile(tmp_path / "again.csv", read_runs(path))  # what is read writes back to the same text
    assert (tmp_path / "again.csv").read_text() == path.read_text()


def test_a_missing_file_is_empty_and_a_torn_row_dropped(tmp_path):
    assert read_runs(tmp_path / "none.csv") == []
    path = tmp_path / FILE_NAME
    RunsFile(path, [ROW])
    path.write_text(path.read_text() + "m,100,1")  # a killed writer's last line
    assert [r["lane"] for r in read_runs(path)] == [0]


def test_runs_file_replaces_atomically(tmp_path, monkeypatch):
    path = tmp_path / FILE_NAME
    runs = RunsFile(path, [ROW])
    runs.append([dict(ROW, lane=1)])
    before = path.read_text()
    assert len(read_runs(path)) == 2

    def interrupted(fd):  # Ctrl-C while the next batch is being written
        raise KeyboardInterrupt

    monkeypatch.setattr(runs_csv.os, "fsync", interrupted)
    with pytest.raises(KeyboardInterrupt):
        runs.append([dict(ROW, lane=2)])
    assert path.read_text() == before  # the previous batch's file, whole
    monkeypatch.undo()
    done, _ = sweep.completed_runs(path, lanes=2)
    assert done == {runs_csv.run_key("m", 0.0, 100.0, 20.0)}


def test_a_row_is_keyed_by_its_run_as_evaluated_and_as_read_back(tmp_path):
    scaled = {"mesh": "m", "k": 40.0, "speed_fpm": 130.0, "condition": "messy", "lane": 0, "mass": 20.0 * 1.1 ** 3,
              "scale": 1.1}
    key = runs_csv.run_key("m", 40.0, 130.0, 20.0, "messy")
    assert runs_csv.row_key(scaled) == key
    RunsFile(tmp_path / FILE_NAME, [scaled])
    assert runs_csv.row_key(read_runs(tmp_path / FILE_NAME)[0]) == key  # six significant digits, same run
    # an error row carries no scale and an older file no condition: an unscaled, tidy run
    assert runs_csv.row_key({"mesh": "m", "k": 0.0, "speed_fpm": 100.0, "mass": 20.0}) == runs_csv.run_key(
        "m", 0.0, 100.0, 20.0)
    assert runs_csv.row_key({"mesh": "m", "k": 0.0, "speed_fpm": 100.0, "mass": 20.0, "scale": math.nan,
                             "condition": ""}) == runs_csv.run_key("m", 0.0, 100.0, 20.0)
