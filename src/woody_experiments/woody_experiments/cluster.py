"""Where `woody sweep` and `woody calibrate` run their evaluations: a Dask cluster.

Without ``--scheduler`` an embedded ``LocalCluster`` (``--jobs`` worker
processes, one thread each) does the work on this machine; with
``--scheduler tcp://HOST:8786`` the same tasks go to an existing cluster
(``dask scheduler`` + ``dask worker`` processes, docker compose, or
dask-jobqueue on SLURM: docs/cluster.md). Either way the client alone owns the
results: workers return rows, the client hands them to ``on_rows`` in
batches (whatever has arrived since the last call), so the CSV writer never
races a worker.

A task carries a :class:`~woody_experiments.experiment.RunSpec` and a *mesh
reference* — a generator seed, a built-in mesh name or a file path — never a
pickled mesh. Each worker process resolves a reference once and keeps the
mesh, and ``experiment`` keeps its renderers per process, so a worker stays
warm from task to task. A worker that dies has its tasks rescheduled by the
scheduler on the others; each task's rows reach the client exactly once.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import threading
import time
import uuid
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import dask
from distributed import Client, LocalCluster, WorkerPlugin, as_completed

from woody_experiments.experiment import RunSpec
from woody_sim.meshes import BUILTIN_DIR, FilletMesh, conversions_noted, generate_fillet, load_mesh

WORKER_WAIT_S = 60.0
"""How long to wait for the first worker of an existing cluster."""
DEFAULT_PROBE_RUNS = 4
"""Runs evaluated one at a time before the parallel phase, the one-worker reference of the scaling efficiency;
the first only warms the worker up (its renderer, compiled kernels, the mesh) and is not timed."""

WORKER_ENVIRON = {"OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1, "OPENBLAS_NUM_THREADS": 1}
"""The environment of a local worker: Dask's default without its MALLOC_TRIM_THRESHOLD_. Setting that switches off
glibc's adaptive mmap threshold, so every frame-sized array was mapped and unmapped afresh: a sweep worker spent
30 % of its time in the kernel zeroing pages."""

MeshRef = tuple[str, str]
Evaluate = Callable[[RunSpec, FilletMesh], list[dict]]

_MESHES: dict[MeshRef, FilletMesh] = {}
_LOADS: Counter = Counter()
_TASKS: Counter = Counter()
_LOCK = threading.Lock()


def add_arguments(parser: argparse.ArgumentParser, jobs_default: int | None, probe: bool = True) -> None:
    """--scheduler and --jobs (and --scaling-probe with ``probe``), shared by `woody sweep` and `woody calibrate`."""
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="run on an existing Dask cluster, e.g. tcp://HOST:8786 (default: an embedded "
                             "LocalCluster on this machine); see docs/cluster.md")
    parser.add_argument("--jobs", type=int, default=jobs_default,
                        help="worker processes of the embedded LocalCluster (default: cores; ignored with --scheduler)")
    if probe:
        parser.add_argument("--scaling-probe", type=int, default=DEFAULT_PROBE_RUNS, metavar="RUNS",
                            help="with more than one worker, evaluate this many runs of one mesh one at a time "
                                 "first to measure the one-worker rate for the scaling efficiency; the first only "
                                 f"warms the worker up (default {DEFAULT_PROBE_RUNS}; 0 or 1: off)")


# ---------------------------------------------------------------- worker side

def mesh_ref(mesh: FilletMesh) -> MeshRef:
    """How any host finds this mesh again: generator seed, built-in name or file path."""
    if mesh.source.startswith("generated:"):
        return ("generated", mesh.source.split(":", 1)[1])
    path = Path(mesh.source)
    if not mesh.source or not path.is_file():
        raise ValueError(f"mesh {mesh.name!r} has no file or generator seed a worker could load it from")
    if path.resolve().parent == BUILTIN_DIR:
        return ("builtin", path.name)
    return ("file", str(path.resolve()))


def load_ref(ref: MeshRef) -> FilletMesh:
    """The mesh a reference names (files of kind "file" must be at the same path on the worker)."""
    kind, value = ref
    if kind == "generated":
        return generate_fillet(int(value))
    with conversions_noted():  # the command that sent the reference said it
        return load_mesh(BUILTIN_DIR / value if kind == "builtin" else value)


def _task(evaluate: Evaluate, run: RunSpec, ref: MeshRef) -> list[dict]:
    """One run on a worker. The lock keeps a multi-threaded worker to one pybullet run at a time per process."""
    with _LOCK:
        if ref not in _MESHES:
            _MESHES[ref] = load_ref(ref)
            _LOADS[ref] += 1
        _TASKS["runs"] += 1
        return evaluate(run, _MESHES[ref])


class WarmWorker(WorkerPlugin):
    """Imports the simulation stack on every worker, current and joining, before its first task."""

    name = "woody-warm"

    def setup(self, worker) -> None:
        import woody_experiments.experiment  # noqa: F401  (pybullet, OpenCV, trimesh: seconds on a cold worker)


def worker_stats() -> dict:
    """What this worker process did: runs evaluated and loads per mesh (each should be 1)."""
    return {"runs": _TASKS["runs"], "loads": {f"{k}:{v}": n for (k, v), n in _LOADS.items()}}


# ---------------------------------------------------------------- client side

class ClusterUnavailable(RuntimeError):
    """The scheduler cannot be reached, or no worker joined in time."""


@contextmanager
def connect(scheduler: str | None, jobs: int, name: str) -> Iterator:
    """A Dask client on the given scheduler, or on an embedded LocalCluster of ``jobs`` one-thread workers."""
    client, cluster = _open(scheduler, jobs)
    try:
        client.register_plugin(WarmWorker())
        _announce(client, name)
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _open(scheduler: str | None, jobs: int) -> tuple:
    cluster = client = None
    try:
        if scheduler:
            client = Client(scheduler, timeout="30s")
        else:
            dask.config.set({"distributed.nanny.pre-spawn-environ": WORKER_ENVIRON})
            cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True, silence_logs=logging.ERROR,
                                   dashboard_address="127.0.0.1:8787")  # another free port if taken
            client = Client(cluster)
        client.wait_for_workers(1, timeout=WORKER_WAIT_S)
    except (OSError, TimeoutError, ValueError) as exc:
        for thing in (client, cluster):
            if thing is not None:
                thing.close()
        where = scheduler or "(local cluster)"
        raise ClusterUnavailable(f"cannot use the Dask cluster {where}: {type(exc).__name__}: {exc}") from exc
    return client, cluster


def _announce(client, name: str) -> None:
    info = client.scheduler_info(n_workers=-1)
    workers = info["workers"]
    threads = sum(w["nthreads"] for w in workers.values())
    print(f"{name}: Dask scheduler {info['address']}, {len(workers)} workers", file=sys.stderr)
    if "dashboard" in info.get("services", {}):
        print(f"{name}: dashboard {client.dashboard_link}", file=sys.stderr)
    if threads > len(workers):
        print(f"{name}: note: workers have {threads} threads in all; woody runs one evaluation at a time per "
              "process, so start workers with --nthreads 1 and --nworkers N", file=sys.stderr)


def worker_count(client) -> int:
    return len(client.scheduler_info(n_workers=-1)["workers"])


@dataclass
class Throughput:
    """What a batch of tasks cost: evaluations (rows) and wall time, overall and for the one-worker probe."""

    evaluations: int = 0
    wall_s: float = 0.0
    workers: int = 1
    warmup_evaluations: int = 0
    warmup_s: float = 0.0
    """The probe's first run: a cold worker, counted in neither rate of the efficiency."""
    probe_evaluations: int = 0
    probe_s: float = 0.0
    failed: list[str] = field(default_factory=list)

    @property
    def per_min(self) -> float:
        return self.evaluations / self.wall_s * 60.0 if self.wall_s > 0 else 0.0

    @property
    def one_worker_per_min(self) -> float | None:
        return self.probe_evaluations / self.probe_s * 60.0 if self.probe_s > 0 else None

    @property
    def parallel_per_min_per_worker(self) -> float | None:
        wall = self.wall_s - self.warmup_s - self.probe_s
        evals = self.evaluations - self.warmup_evaluations - self.probe_evaluations
        return evals / wall * 60.0 / self.workers if wall > 0 and evals > 0 else None

    @property
    def efficiency(self) -> float | None:
        """Evaluations/min/worker in the parallel phase over the one-worker rate of the probe."""
        one, par = self.one_worker_per_min, self.parallel_per_min_per_worker
        return par / one if one and par and self.workers > 1 else None

    def summary(self) -> str:
        text = f"{self.evaluations} fillet evaluations in {self.wall_s:.1f} s = {self.per_min:.0f} /min"
        if self.efficiency is not None:
            text += (f"; {self.workers} workers: {self.parallel_per_min_per_worker:.1f} /min/worker against "
                     f"{self.one_worker_per_min:.1f} /min with one warm worker alone ({self.probe_evaluations} "
                     f"evaluations of one mesh, same sweep): scaling efficiency {self.efficiency * 100:.0f} %")
        return text

    def as_meta(self) -> dict:
        eff = self.efficiency
        return {"workers": self.workers, "one_worker_per_min": _round(self.one_worker_per_min),
                "per_min_per_worker": _round(self.parallel_per_min_per_worker),
                "scaling_efficiency": None if eff is None else round(eff, 3)}


def _round(value: float | None) -> float | None:
    return None if value is None else round(value, 2)


def probe_order(runs: list, probe: int) -> list:
    """The runs with ``probe`` of the first mesh's, spread over its k and speeds, moved to the front.

    One mesh, loaded by the untimed first probe run, so the timed ones measure a warm worker (the parallel
    phase loads each mesh once per worker among hundreds of runs).
    """
    if probe <= 0 or probe >= len(runs):
        return list(runs)
    first = [i for i, run in enumerate(runs) if run.mesh == runs[0].mesh]
    step = len(first) / min(probe, len(first))
    picked = sorted({first[int(i * step)] for i in range(min(probe, len(first)))})
    chosen = set(picked)
    return [runs[i] for i in picked] + [r for i, r in enumerate(runs) if i not in chosen]


def run_tasks(client, evaluate: Evaluate, runs: list[RunSpec], meshes: dict[str, FilletMesh],
              on_rows: Callable[[list[dict]], None], desc: str, probe: int = 0, unit: str = "evals") -> Throughput:
    """Evaluate every run on the cluster; ``on_rows`` gets each batch of finished rows on the client.

    With ``probe`` > 1 and more than one worker, the first ``probe`` runs go
    one at a time (one worker busy) to measure the one-worker rate, all but
    the first (the worker's warm-up) timed. A task
    that fails on the cluster (its mesh cannot be loaded there, or it killed
    workers) gives no rows and is listed in ``failed``. The progress bar shows rows per minute, named ``unit``.
    """
    from tqdm import tqdm

    refs = {name: mesh_ref(mesh) for name, mesh in meshes.items()}
    stats = Throughput(workers=worker_count(client))
    probe = probe if stats.workers > 1 and len(runs) > probe > 1 else 0
    tag = uuid.uuid4().hex[:8]
    start = time.perf_counter()

    def submit(i: int, run: RunSpec):
        key = f"woody-run-{run.mesh}-k{run.k:g}-{run.speed_fpm:g}fpm-{tag}-{i}"
        return client.submit(_task, evaluate, run, refs[run.mesh], key=key, pure=False)

    with tqdm(total=len(runs), unit="run", desc=desc, dynamic_ncols=True, file=sys.stderr) as bar:
        def collect(futures: list, batches: bool) -> None:
            _gather(futures, stats, on_rows, bar, start, batches, unit)

        for i, run in enumerate(runs[:probe]):
            collect([submit(i, run)], batches=False)
            if i == 0:
                stats.warmup_evaluations, stats.warmup_s = stats.evaluations, time.perf_counter() - start
        if probe:
            stats.probe_evaluations = stats.evaluations - stats.warmup_evaluations
            stats.probe_s = time.perf_counter() - start - stats.warmup_s
        collect([submit(i, run) for i, run in enumerate(runs[probe:], probe)], batches=True)
    stats.wall_s = time.perf_counter() - start
    return stats


def _gather(futures: list, stats: Throughput, on_rows, bar, start: float, batches: bool, unit: str) -> None:
    """Hand rows to ``on_rows`` as tasks finish, one call per burst of finished tasks."""
    done = as_completed(futures)
    pending: list[dict] = []
    try:
        for future in done:
            try:
                pending += future.result()
            except Exception as exc:  # a task the cluster could not run: no rows, reported by the caller
                stats.failed.append(f"{future.key}: {type(exc).__name__}: {exc}")
            bar.update(1)
            if not (batches and done.has_ready()):
                _hand_over(pending, stats, on_rows)
            bar.set_postfix_str(f"{stats.evaluations / max(time.perf_counter() - start, 1e-9) * 60:.0f} {unit}/min")
    except BaseException:
        _hand_over(pending, stats, on_rows)  # Ctrl-C: keep what arrived, stop the rest
        for future in futures:
            future.cancel()
        raise


def _hand_over(rows: list[dict], stats: Throughput, on_rows) -> None:
    batch = rows[:]
    rows.clear()  # before the write: an interrupted write loses the batch (redone on resume), never doubles it
    if batch:
        on_rows(batch)
        stats.evaluations += len(batch)


def describe_workers(client) -> str:
    """One line on what the live workers did: runs each, and whether any loaded a mesh twice."""
    stats = client.run(worker_stats)
    runs = sorted((s["runs"] for s in stats.values()), reverse=True)
    loads = [n for s in stats.values() for n in s["loads"].values()]
    meshes = {m for s in stats.values() for m in s["loads"]}
    return (f"{len(stats)} live workers ran {runs} runs; {len(meshes)} meshes, {sum(loads)} loads "
            f"({'each worker loaded each mesh once' if all(n == 1 for n in loads) else 'some loaded twice'})")


def default_jobs() -> int:
    return os.cpu_count() or 1
