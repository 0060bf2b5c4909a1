"""Honest classification figures: per mesh set, one vote per run, Wilson intervals, leave-one-mesh-out.

The lanes of one run carry the same mesh at the same k and speed (one
simulated chain, posed into every lane: ``experiment._LaneCopies``); they
differ only by the camera's perspective, so they are not independent samples. Here a
*unit* is one run (mesh × k × speed × mass) and its Φ is the median over its
scored lanes: with three lanes that is the lane majority's vote. Accuracy is
counted over units, with a 95 % Wilson score interval, and every figure says
how many distinct meshes stand behind it.

Mesh sets: names starting with ``generated-`` are generated fillets; every
other mesh (``seed0000``.. and scans from a folder) is a reference (real) mesh.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from woody_common.line import NORMAL_K, SEVERE_K
from woody_experiments.paper_targets import ACCURACY_MIN
from woody_experiments.statistics import accuracy, best_threshold, wilson_interval

SET_REFERENCE = "reference"
SET_GENERATED = "generated"


def mesh_set(name: str) -> str:
    """'generated' for generated fillets, 'reference' for real meshes."""
    return SET_GENERATED if name.startswith("generated-") else SET_REFERENCE


@dataclass(frozen=True)
class Unit:
    """One run as one vote: the median Φ over its scored lanes."""

    mesh: str
    k: float
    speed_fpm: float
    phi: float
    lanes: int
    """Scored lanes behind the median."""


def run_units(rows: Sequence[dict]) -> list[Unit]:
    """Runs of scored normal (k = 0) and severe (k = 100) rows, each reduced to its median Φ over lanes."""
    groups: dict[tuple, list[float]] = {}
    for r in rows:
        if r.get("status") != "scored" or not math.isfinite(r["phi"]):
            continue
        if not any(math.isclose(r["k"], k) for k in (NORMAL_K, SEVERE_K)):
            continue
        groups.setdefault((r["mesh"], r["k"], r["speed_fpm"], r.get("mass")), []).append(r["phi"])
    return [Unit(mesh, k, speed, float(np.median(phis)), len(phis))
            for (mesh, k, speed, _), phis in sorted(groups.items(), key=lambda kv: str(kv[0]))]


def split(units: Sequence[Unit]) -> tuple[list[float], list[float]]:
    """(normal Φ, severe Φ) of the units."""
    return ([u.phi for u in units if math.isclose(u.k, NORMAL_K)],
            [u.phi for u in units if math.isclose(u.k, SEVERE_K)])


@dataclass(frozen=True)
class Score:
    """Accuracy of the reject rule at a threshold (statistics.accuracy) on a set of units."""

    right: int
    total: int
    meshes: int
    """Distinct meshes behind the units."""
    threshold: float

    @property
    def accuracy(self) -> float:
        return self.right / self.total if self.total else math.nan

    @property
    def interval(self) -> tuple[float, float]:
        return wilson_interval(self.right, self.total)

    def text(self) -> str:
        lo, hi = self.interval
        if not self.total:
            return "— (no runs)"
        meshes = f"{self.meshes} mesh" + ("es" if self.meshes != 1 else "")
        return (f"{self.accuracy * 100:.1f} % ({self.right}/{self.total} runs, {meshes}; "
                f"95 % CI {lo * 100:.1f}–{hi * 100:.1f} %)")


def score(units: Sequence[Unit], threshold: float) -> Score:
    """Accuracy of the units at a threshold."""
    normal, severe = split(units)
    _, right, total = accuracy(normal, severe, threshold)
    return Score(right, total, len({u.mesh for u in units}), threshold)


@dataclass(frozen=True)
class Fold:
    """One leave-one-mesh-out fold: threshold chosen on the other meshes, scored on the held-out one."""

    held_out: str
    threshold: float
    train_balanced_accuracy: float
    test: Score


def leave_one_out(units: Sequence[Unit]) -> list[Fold]:
    """Each mesh held out once; its threshold is the best balanced-accuracy cut on the other meshes' units."""
    meshes = sorted({u.mesh for u in units})
    folds = []
    for held in meshes:
        train = [u for u in units if u.mesh != held]
        normal, severe = split(train)
        if not normal or not severe:
            continue
        threshold, bacc = best_threshold(normal, severe)
        folds.append(Fold(held, threshold, bacc, score([u for u in units if u.mesh == held], threshold)))
    return folds


def pooled(folds: Sequence[Fold]) -> Score:
    """All held-out units of the folds together (each scored with its own fold's threshold)."""
    right = sum(f.test.right for f in folds)
    total = sum(f.test.total for f in folds)
    return Score(right, total, len(folds), math.nan)


def phi_ratio(units: Sequence[Unit]) -> float:
    """Mean normal Φ over mean severe Φ."""
    normal, severe = split(units)
    return float(np.mean(normal) / np.mean(severe)) if normal and severe else math.nan


def report(rows: Sequence[dict], threshold: float) -> tuple[list[str], list[tuple[str, bool | None, str]]]:
    """Markdown lines of the per-set and leave-one-out sections, and the target checks they decide."""
    units = run_units(rows)
    speeds = sorted({u.speed_fpm for u in units})
    lines = ["## Classification per mesh set (one vote per run)\n",
             "A run is one mesh at one k and speed; its lanes differ only by perspective and are not independent, so "
             "each run counts once, with the median Φ of its scored lanes (the lane majority's vote). Reference = "
             "real meshes, generated = `generated-*`. Intervals are 95 % Wilson score intervals over runs.\n",
             f"| set | FPM | meshes | runs normal / severe | Φ(k=0)/Φ(k=100) | accuracy at {threshold:g} |",
             "|---|---|---|---|---|---|"]
    checks: list[tuple[str, bool | None, str]] = []
    for name in (SET_REFERENCE, SET_GENERATED):
        for speed in speeds:
            sel = [u for u in units if mesh_set(u.mesh) == name and math.isclose(u.speed_fpm, speed)]
            if not sel:
                continue
            normal, severe = split(sel)
            lines.append(f"| {name} | {speed:g} | {len({u.mesh for u in sel})} | {len(normal)} / {len(severe)} | "
                         f"{phi_ratio(sel):.2f} | {score(sel, threshold).text()} |")
            if name == SET_REFERENCE and math.isclose(speed, 100.0) and normal and severe:
                checks.append(("reference meshes, 100 FPM: Φ(k=0)/Φ(k=100) ≥ 3.0", phi_ratio(sel) >= 3.0,
                               f"{np.mean(normal):.2f} / {np.mean(severe):.2f} = {phi_ratio(sel):.2f} "
                               f"({len({u.mesh for u in sel})} meshes)"))
    lines.append("")
    lines += _loo_lines(rows, units, speeds, checks)
    return lines, checks


def lane_score(rows: Sequence[dict], mesh: str, speed: float, threshold: float) -> tuple[int, int]:
    """(right, total) over the scored normal and severe lanes of one mesh at one speed (lanes not independent)."""
    sel = [r for r in rows if r["mesh"] == mesh and math.isclose(r["speed_fpm"], speed)
           and r.get("status") == "scored" and math.isfinite(r["phi"])]
    normal = [r["phi"] for r in sel if math.isclose(r["k"], NORMAL_K)]
    severe = [r["phi"] for r in sel if math.isclose(r["k"], SEVERE_K)]
    _, right, total = accuracy(normal, severe, threshold)
    return right, total


def _loo_lines(rows: Sequence[dict], units: Sequence[Unit], speeds: Sequence[float], checks: list) -> list[str]:
    lines = ["## Leave-one-out over the reference meshes\n",
             "Per speed: the threshold is the best balanced-accuracy cut on the runs of all reference meshes but one, "
             "and is scored on the held-out mesh's runs; every reference mesh is held out once.\n",
             "| FPM | held-out mesh | threshold from the others | their balanced accuracy | held-out accuracy | "
             "held-out lanes |",
             "|---|---|---|---|---|---|"]
    for speed in speeds:
        ref = [u for u in units if mesh_set(u.mesh) == SET_REFERENCE and math.isclose(u.speed_fpm, speed)]
        folds = leave_one_out(ref)
        lanes = [lane_score(rows, fold.held_out, speed, fold.threshold) for fold in folds]
        for fold, (right, n) in zip(folds, lanes):
            lines.append(f"| {speed:g} | {fold.held_out} | {fold.threshold:.2f} | "
                         f"{fold.train_balanced_accuracy * 100:.1f} % | {fold.test.text()} | {right}/{n} |")
        if folds:
            total = pooled(folds)
            lines.append(f"| {speed:g} | **all folds** | — | — | {total.text()} | "
                         f"{sum(r for r, _ in lanes)}/{sum(n for _, n in lanes)} |")
            if math.isclose(speed, 100.0):
                checks.append((f"reference meshes, 100 FPM: leave-one-out accuracy ≥ {ACCURACY_MIN * 100:.0f} %",
                               total.accuracy >= ACCURACY_MIN,
                               total.text()))
    if len(lines) == 4:
        lines.append("| — | fewer than two reference meshes with k = 0 and k = 100 runs | — | — | — | — |")
    lines.append("")
    return lines
