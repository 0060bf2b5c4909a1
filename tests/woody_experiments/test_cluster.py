"""`woody sweep` on Dask: a real `dask scheduler` and two `dask worker` processes on 127.0.0.1.

Equality of a cluster sweep with a local one is defined as: the same run keys
(mesh, k, speed, lane, mass), the same status, and every metric within
``REL_TOL`` of the other. REL_TOL only absorbs the 6-significant-digit CSV
formatting: repeated sweeps of this grid (fork pool, LocalCluster, two
external workers) gave byte-identical values (docs/cluster.md), i.e. pybullet
showed no run-to-run variation here.
"""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from woody_common.calibration import resolved_calibration
from woody_experiments import cluster
from woody_experiments.experiment import RunSpec
from woody_sim.meshes import BUILTIN_DIR, generate_fillet, load_mesh

DASK = Path(sys.executable).parent / "dask"
GRID = ["--meshes", "generated:1:7", "--k", "0,50,100", "--speeds", "100", "--lanes", "1", "--no-report"]
METRICS = ("phi", "hu_term", "solidity_term", "nmdm", "mdm", "be")
REL_TOL = 1e-5


def _woody(*args: str, timeout: float = 240) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-c", "import sys; from woody_tools.cli import main; sys.exit(main(sys.argv[1:]))", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)


def _rows(path: Path) -> dict[tuple, dict]:
    with path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    keyed = {(r["mesh"], float(r["k"]), float(r["speed_fpm"]), int(r["lane"]), float(r["mass"])): r for r in rows}
    assert len(keyed) == len(rows), "a run key appears twice"
    return keyed


def _same(a: str, b: str) -> bool:
    if a == "" or b == "":
        return a == b
    return math.isclose(float(a), float(b), rel_tol=REL_TOL)


@pytest.fixture
def dask_cluster(tmp_path):
    """A scheduler and two one-thread workers (no nanny, so a killed worker stays dead) on free ports.

    Yields (scheduler address, worker processes).
    """
    procs: list[subprocess.Popen] = []
    logs = []

    def start(name: str, *args: str) -> subprocess.Popen:
        log = open(tmp_path / f"{name}.log", "w")
        logs.append(log)
        procs.append(subprocess.Popen([str(DASK), *args], stdout=log, stderr=subprocess.STDOUT))
        return procs[-1]

    info = tmp_path / "scheduler.json"
    start("scheduler", "scheduler", "--host", "127.0.0.1", "--port", "0", "--dashboard-address", "127.0.0.1:0",
          "--scheduler-file", str(info))
    deadline = time.monotonic() + 60
    while not (info.exists() and info.stat().st_size):
        assert time.monotonic() < deadline and procs[0].poll() is None, (tmp_path / "scheduler.log").read_text()
        time.sleep(0.2)
    address = json.loads(info.read_text())["address"]
    workers = [start(f"worker{i}", "worker", address, "--nthreads", "1", "--no-nanny", "--host", "127.0.0.1",
                     "--dashboard-address", "127.0.0.1:0", "--name", f"w{i}") for i in range(2)]
    from distributed import Client

    with Client(address, timeout="30s") as client:
        client.wait_for_workers(2, timeout=90)
    yield address, workers
    for proc in reversed(procs):
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
    for log in logs:
        log.close()


@pytest.mark.slow
def test_scheduler_sweep_equals_local_and_resumes(dask_cluster, tmp_path):
    address, _ = dask_cluster
    local = _woody("sweep", *GRID, "--jobs", "1", "--out", str(tmp_path / "local"))
    assert local.returncode == 0, local.stderr[-3000:]
    remote = _woody("sweep", *GRID, "--scheduler", address, "--scaling-probe", "2", "--out", str(tmp_path / "remote"))
    assert remote.returncode == 0, remote.stderr[-3000:]
    assert f"Dask scheduler {address}, 2 workers" in remote.stderr
    assert "woody sweep: dashboard http://127.0.0.1:" in remote.stderr
    assert "scaling efficiency" in remote.stderr and "each worker loaded each mesh once" in remote.stderr

    a, b = _rows(tmp_path / "local" / "runs.csv"), _rows(tmp_path / "remote" / "runs.csv")
    assert len(a) == 3 and a.keys() == b.keys()
    for key, row in a.items():
        assert row["status"] == b[key]["status"] == "scored", (row, b[key])
        for column in METRICS:
            assert _same(row[column], b[key][column]), (key, column, row[column], b[key][column])

    # resume: runs the local cluster computed are skipped by the external one
    before = (tmp_path / "local" / "runs.csv").read_text()
    again = _woody("sweep", *GRID, "--scheduler", address, "--out", str(tmp_path / "local"))
    assert again.returncode == 0, again.stderr[-3000:]
    assert "0 to go" in again.stderr
    assert (tmp_path / "local" / "runs.csv").read_text() == before


@pytest.mark.slow
def test_worker_killed_mid_sweep_loses_and_doubles_nothing(dask_cluster, tmp_path):
    from distributed import Client

    address, workers = dask_cluster
    out = tmp_path / "killed"
    grid = ["--meshes", "generated:1:7", "--k", "0,50,100", "--speeds", "100", "--lanes", "1", "--no-report",
            "--scaling-probe", "0"]
    cmd = [sys.executable, "-c", "import sys; from woody_tools.cli import main; sys.exit(main(sys.argv[1:]))",
           "sweep", *grid, "--scheduler", address, "--out", str(out)]
    with (tmp_path / "sweep.log").open("w") as log:
        sweep = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
        victim = workers[1]
        with Client(address, timeout="30s") as client:
            deadline = time.monotonic() + 120
            while not _busy(client, "w1"):  # kill it while it holds a task
                assert time.monotonic() < deadline and sweep.poll() is None, (tmp_path / "sweep.log").read_text()
                time.sleep(0.05)
            os.kill(victim.pid, signal.SIGKILL)
            assert sweep.wait(240) == 0, (tmp_path / "sweep.log").read_text()[-3000:]
            assert len(client.scheduler_info(n_workers=-1)["workers"]) == 1
    rows = _rows(out / "runs.csv")  # asserts no key twice
    mass = resolved_calibration().total_mass_kg
    assert sorted(rows) == sorted(("generated-70000", k, 100.0, lane, mass) for k in (0.0, 50.0, 100.0)
                                  for lane in range(1))
    assert all(r["status"] == "scored" for r in rows.values())
    assert "not computed" not in (tmp_path / "sweep.log").read_text()


def _busy(client, name: str) -> bool:
    workers = client.scheduler_info(n_workers=-1)["workers"]
    processing = client.processing()
    return any(info.get("name") == name and processing.get(addr) for addr, info in workers.items())


# ---------------------------------------------------------------- plain functions, no cluster

def test_mesh_refs_name_meshes_any_host_can_load(tmp_path):
    generated = generate_fillet(70001)
    assert cluster.mesh_ref(generated) == ("generated", "70001")
    builtin = load_mesh(BUILTIN_DIR / "seed0000.obj")
    assert cluster.mesh_ref(builtin) == ("builtin", "seed0000.obj")
    copy = tmp_path / "mine.obj"
    copy.write_bytes((BUILTIN_DIR / "seed0001.obj").read_bytes())
    mine = load_mesh(copy)
    assert cluster.mesh_ref(mine) == ("file", str(copy.resolve()))
    for mesh in (generated, builtin, mine):
        again = cluster.load_ref(cluster.mesh_ref(mesh))
        assert again.name == mesh.name
        assert (again.mesh.vertices == mesh.mesh.vertices).all()
    copy.unlink()
    with pytest.raises(ValueError, match="no file or generator seed"):
        cluster.mesh_ref(mine)


def test_task_loads_each_mesh_once_per_process(monkeypatch):
    monkeypatch.setattr(cluster, "_MESHES", {})
    monkeypatch.setattr(cluster, "_LOADS", cluster.Counter())
    seen = []
    for k in (0.0, 100.0):
        cluster._task(lambda run, mesh: seen.append(mesh) or [{"k": run.k}], RunSpec("generated-70001", k, 100.0),
                      ("generated", "70001"))
    assert seen[0] is seen[1]
    assert cluster.worker_stats()["loads"] == {"generated:70001": 1}


def test_probe_order_spreads_the_probe_over_the_first_mesh_s_runs():
    runs = [RunSpec(mesh, k, 100.0) for mesh in ("a", "b") for k in range(6)]
    assert cluster.probe_order(runs, 0) == runs
    ordered = cluster.probe_order(runs, 3)
    assert [(r.mesh, r.k) for r in ordered[:3]] == [("a", 0), ("a", 2), ("a", 4)]
    assert sorted(ordered, key=runs.index) == runs
    assert [r.mesh for r in cluster.probe_order(runs, 8)[:6]] == ["a"] * 6  # no more than the first mesh has
    assert cluster.probe_order(runs, 12) == runs


def test_scaling_efficiency_compares_per_worker_rate_with_one_warm_worker_alone():
    stats = cluster.Throughput(evaluations=69, wall_s=45.0, workers=2, warmup_evaluations=3, warmup_s=5.0,
                               probe_evaluations=6, probe_s=10.0)
    assert stats.one_worker_per_min == pytest.approx(36.0)
    assert stats.parallel_per_min_per_worker == pytest.approx(60.0 / 30.0 * 60.0 / 2)  # neither warm-up nor probe
    assert stats.efficiency == pytest.approx(60.0 / 36.0)
    assert "scaling efficiency 167 %" in stats.summary() and "one warm worker alone" in stats.summary()
    assert cluster.Throughput(evaluations=6, wall_s=3.0, workers=1).efficiency is None


def _broken(run: RunSpec, mesh) -> list[dict]:
    raise RuntimeError("boom")


def test_a_task_the_cluster_cannot_run_gives_no_rows_and_is_listed():
    from distributed import Client, LocalCluster

    got: list[dict] = []
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address="127.0.0.1:0") as local, \
            Client(local) as client:
        stats = cluster.run_tasks(client, _broken, [RunSpec("generated-70001", 0.0, 100.0)],
                                  {"generated-70001": generate_fillet(70001)}, got.extend, "test")
    assert got == [] and stats.evaluations == 0
    assert len(stats.failed) == 1 and "RuntimeError: boom" in stats.failed[0]
