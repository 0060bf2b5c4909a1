"""`woody sweep --traces`: Φ and its two terms for every frame of every fillet's window, as CSV and plots.

A misgraded fillet is then seen, not guessed at: a k-independent jump in one
frame, a term that dominates, a window that closes late. Each run writes its
own file ``traces/runs/<run>.csv`` (atomically, so a killed sweep leaves no
half file and a rerun knows which runs are traced); the report step joins
them into ``traces.csv`` and draws one plot per mesh and speed,
``traces/<mesh>_<speed>fpm.png``: Φ_t, w1·Hu_t and w2·Sol_t against time
before the window closes, one colour per k, one line per lane.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Sequence
from pathlib import Path

from woody_experiments.conditions import TIDY
from woody_experiments.runs_csv import row_key

TRACE_DIR = "traces"
TRACE_CSV = "traces.csv"
COLUMNS = ["mesh", "k", "speed_fpm", "mass", "lane", "frame", "t_rel_s", "phi", "hu_term", "solidity_term"]


def run_file(out: Path, mesh: str, k: float, speed: float, mass: float, condition: str = TIDY) -> Path:
    """Where one run's traces go (``mass`` before size scaling)."""
    suffix = "" if condition == TIDY else f"_{condition}"
    return Path(out) / TRACE_DIR / "runs" / f"{mesh}_k{k:g}_{speed:g}fpm_M{mass:g}{suffix}.csv"


def write_runs(out: Path, rows: Sequence[dict]) -> list[Path]:
    """Write the traces of a batch of lane rows, one file per run (a batch may hold several runs that finished
    together); returns the files written."""
    by_file: dict[Path, list[dict]] = {}
    for row in rows:
        by_file.setdefault(run_file(out, *row_key(row)), []).append(row)
    for path, run_rows in by_file.items():
        _write(path, run_rows)
    return list(by_file)


def _write(path: Path, rows: Sequence[dict]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    with tmp.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS)
        writer.writeheader()
        for row in rows:
            for i, frame in enumerate(row.get("trace", [])):
                writer.writerow({"mesh": row["mesh"], "k": row["k"], "speed_fpm": row["speed_fpm"],
                                 "mass": row["mass"], "lane": row["lane"], "frame": i,
                                 **{c: f"{frame[c]:.6g}" for c in ("t_rel_s", "phi", "hu_term", "solidity_term")}})
        fh.flush()
        os.fsync(fh.fileno())
    tmp.replace(path)


def join(out: Path) -> list[dict]:
    """Every run's traces joined into ``out/traces.csv``; returns the rows with numeric values."""
    out = Path(out)
    rows: list[dict] = []
    for path in sorted((out / TRACE_DIR / "runs").glob("*.csv")):
        with path.open(newline="") as fh:
            rows += list(csv.DictReader(fh))
    with (out / TRACE_CSV).open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    for row in rows:
        for c in COLUMNS[1:]:
            row[c] = float(row[c]) if row[c] != "" else math.nan
    return rows


def plot(out: Path, rows: Sequence[dict], w1: float, w2: float, threshold: float) -> list[Path]:
    """One PNG per mesh and speed; returns the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    groups: dict[tuple[str, float], list[dict]] = {}
    for row in rows:
        groups.setdefault((row["mesh"], row["speed_fpm"]), []).append(row)
    for (mesh, speed), group in sorted(groups.items()):
        ks = sorted({r["k"] for r in group})
        colours = plt.get_cmap("viridis")([i / max(1, len(ks) - 1) for i in range(len(ks))])
        fig, axes = plt.subplots(3, 1, figsize=(6.4, 7.2), sharex=True)
        for colour, k in zip(colours, ks):
            for lane in sorted({r["lane"] for r in group if r["k"] == k}):
                frames = sorted((r for r in group if r["k"] == k and r["lane"] == lane), key=lambda r: r["frame"])
                t = [r["t_rel_s"] for r in frames]
                label = f"k={k:g}" if lane == min(r["lane"] for r in group if r["k"] == k) else None
                style = dict(color=colour, marker=".", lw=1.0, ls=("-", "--", ":")[int(lane) % 3])
                axes[0].plot(t, [r["phi"] for r in frames], label=label, **style)
                axes[1].plot(t, [w1 * r["hu_term"] for r in frames], **style)
                axes[2].plot(t, [w2 * r["solidity_term"] for r in frames], **style)
        axes[0].axhline(threshold, color="grey", lw=0.8, ls=":")
        for ax, name in zip(axes, ("Φ_t", f"{w1:g}·Hu term", f"{w2:g}·solidity term")):
            ax.set_ylabel(name)
            ax.grid(alpha=0.3)
        axes[0].set_title(f"{mesh}, {speed:g} FPM: window frame by frame (lanes: - -- :)", fontsize=9)
        axes[0].legend(fontsize=7, ncol=2)
        axes[2].set_xlabel("time before the window closes (s)")
        fig.tight_layout()
        path = Path(out) / TRACE_DIR / f"{mesh}_{speed:g}fpm.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        written.append(path)
    return written
