"""`woody sweep --traces` files: one atomic CSV per run, joined into traces.csv, one plot per mesh and speed."""

from __future__ import annotations

import csv

from woody_experiments import traces


def lane_row(mesh: str, k: float, lane: int, frames: int) -> dict:
    trace = [{"t_rel_s": (i - frames + 1) / 30.0, "phi": 1.0 + i + k / 100.0, "hu_term": 0.01 * i,
              "solidity_term": 0.001 * i} for i in range(frames)]
    return {"mesh": mesh, "k": k, "speed_fpm": 100.0, "mass": 20.0, "lane": lane, "trace": trace}


def test_run_files_join_and_plot(tmp_path):
    for k in (0.0, 100.0):
        paths = traces.write_runs(tmp_path, [lane_row("seed0002", k, lane, 4 + lane) for lane in range(3)])
        assert paths == [traces.run_file(tmp_path, "seed0002", k, 100.0, 20.0)] and paths[0].exists()
    # a run whose lanes have no scored frame still gets its (header-only) file: the run is traced
    [empty] = traces.write_runs(tmp_path, [{**lane_row("generated-0001", 0.0, 0, 0), "trace": []}])
    with empty.open() as fh:
        assert list(csv.reader(fh)) == [traces.COLUMNS]
    assert not list((tmp_path / traces.TRACE_DIR / "runs").glob("*.tmp"))

    rows = traces.join(tmp_path)
    assert len(rows) == 2 * (4 + 5 + 6)
    first = [r for r in rows if r["k"] == 100.0 and r["lane"] == 2]
    assert [r["frame"] for r in first] == [0, 1, 2, 3, 4, 5] and first[-1]["t_rel_s"] == 0.0
    assert first[-1]["phi"] == 7.0 and first[-1]["hu_term"] == 0.05
    with (tmp_path / traces.TRACE_CSV).open() as fh:
        assert len(list(csv.DictReader(fh))) == len(rows)

    plots = traces.plot(tmp_path, rows, 100.0, 100.0, threshold=6.0)
    assert plots == [tmp_path / traces.TRACE_DIR / "seed0002_100fpm.png"]
    assert plots[0].stat().st_size > 5000


def test_a_batch_of_runs_that_finished_together_gets_one_file_per_run(tmp_path):
    batch = [lane_row(mesh, k, lane, 3) for mesh in ("seed0002", "seed0005") for k in (0.0, 100.0) for lane in range(3)]
    paths = traces.write_runs(tmp_path, batch)
    assert paths == [traces.run_file(tmp_path, mesh, k, 100.0, 20.0) for mesh in ("seed0002", "seed0005")
                     for k in (0.0, 100.0)]
    for path in paths:
        with path.open(newline="") as fh:
            assert len({(r["mesh"], r["k"]) for r in csv.DictReader(fh)}) == 1
