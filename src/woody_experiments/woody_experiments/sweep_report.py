"""results.md and plots of a `woody sweep`: the paper's three tables, the project's figures beside the paper's.

Every cell is the project's mean ± sd with the paper's figure next to it (the
paper's figures and the targets are data in :mod:`woody_experiments.paper_targets`).
The report also checks the reproduction targets explicitly (PASS / MISS with
the numbers), prints the sweep throughput and projects the wall time of
the paper's full grid (1,000 meshes x 6 k x 2 speeds x 3 lanes).
"""

from __future__ import annotations

import math
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from woody_common.calibration import Calibration, resolved_calibration
from woody_common.line import NORMAL_K, PAPER_SPEEDS_FPM, SEVERE_K
from woody_experiments import evaluation, line_grade, runs_csv
from woody_experiments.conditions import TIDY
from woody_experiments.paper_targets import (
    ACCURACY_MIN,
    DELTA_NMDM_RANGE,
    NMDM_NORMAL_RANGE,
    PAPER_BIOLOGICAL,
    PAPER_DELTA_NMDM,
    PAPER_LANES,
    PAPER_SIDE,
    PAPER_TOP,
    PHI_RATIO_MIN,
    PHI_SD_FACTOR,
    PHI_SPEED_DROP_MIN,
    PHYSICAL_DELTA_NMDM,
    SPEED_GAIN_MIN,
)
from woody_experiments.runs_csv import read_runs
from woody_experiments.statistics import accuracy, best_threshold, finite, mean_sd, roc, share_text
from woody_sim.meshes import load_mesh_set
from woody_vision.grader_core import calibrated_range, calibrated_rules

FULL_GRID_EVALS = 1000 * 6 * 2 * 3
GOAL_EVALS_PER_MIN = 150.0

PLOTS = ("phi_vs_k.png", "nmdm_vs_k.png", "phi_per_lane.png", "roc.png")

def _plot_beside_paper(ax, rows: Sequence[dict], speed: float, ks: Sequence[float], column: str,
                       paper: dict | None, color) -> None:
    """The project's mean ± sd of ``column`` per k at one speed, and the paper's first column as a dashed line."""
    stats = [mean_sd(_select(rows, speed, k, column=column)) for k in ks]
    ax.errorbar(ks, [s[0] for s in stats], yerr=[s[1] for s in stats], marker="o", capsize=3, color=color,
                label=f"project {speed:g} FPM")
    if paper:
        pk = sorted(paper)
        ax.plot(pk, [paper[k][0] for k in pk], "--", marker="x", color=color, alpha=0.6, label=f"paper {speed:g} FPM")


# ------------------------------------------------------------------ selection helpers

def physics_checks(rows: list[dict], side_rows: list[dict]) -> list[tuple[str, bool | None, str]]:
    """The physics calibration's targets: k = 0 speed effects, BE falling with k, the spread of Φ per class."""
    checks = []
    n = {s: mean_sd(_select(side_rows, s, 0.0, column="nmdm"))[0] for s in PAPER_SPEEDS_FPM}
    if all(math.isfinite(v) for v in n.values()):
        checks.append((f"side: NMDM(k=0) at 130 FPM ≥ {SPEED_GAIN_MIN} above 100 FPM",
                       n[130.0] - n[100.0] >= SPEED_GAIN_MIN,
                       f"{n[130.0]:.3f} − {n[100.0]:.3f} = {n[130.0] - n[100.0]:+.3f} (paper +0.155)"))
    be = [(k, mean_sd(_select(side_rows, 100.0, k, column="be"))[0]) for k in sorted({r["k"] for r in side_rows})]
    be = [(k, v) for k, v in be if math.isfinite(v)]
    if len(be) >= 2:
        checks.append(("side 100 FPM: BE falls monotonically with k",
                       all(b < a for (_, a), (_, b) in zip(be, be[1:])),
                       ", ".join(f"k={k:g}: {v:.1f}" for k, v in be) + " (paper k=0 37.6, k=100 19.3)"))
    phi = {s: mean_sd(_select(rows, s, 0.0))[0] for s in PAPER_SPEEDS_FPM}
    if all(math.isfinite(v) for v in phi.values()):
        drop = 1.0 - phi[130.0] / phi[100.0]
        checks.append((f"top: Φ(k=0) at 130 FPM ≥ {PHI_SPEED_DROP_MIN:.0%} below 100 FPM", drop >= PHI_SPEED_DROP_MIN,
                       f"{phi[130.0]:.2f} vs {phi[100.0]:.2f}: {drop:.0%} lower (paper 14.91 vs 19.12: 22 %)"))
    for k in (0.0, 100.0):
        sd, paper = mean_sd(_select(rows, 100.0, k))[1], PAPER_TOP.get(100.0, {}).get(k)
        if paper is not None and math.isfinite(sd):
            ratio = sd / paper[1]
            checks.append((f"top 100 FPM: Φ sd at k={k:g} within ×{PHI_SD_FACTOR} of the paper's",
                           1.0 / PHI_SD_FACTOR <= ratio <= PHI_SD_FACTOR, f"{sd:.2f} vs {paper[1]:.2f} (×{ratio:.2f})"))
    return checks


def _select(rows, speed=None, k=None, lane=None, column="phi"):
    out = []
    for r in rows:
        if speed is not None and not math.isclose(r["speed_fpm"], speed):
            continue
        if k is not None and not math.isclose(r["k"], k):
            continue
        if lane is not None and r["lane"] != lane:
            continue
        if column == "phi" and r.get("status") != "scored":
            continue
        out.append(r[column])
    return finite(out)


def _fmt(m: float, sd: float, n: int, digits: int) -> str:
    if n == 0 or not math.isfinite(m):
        return "—"
    return f"{m:.{digits}f} ± {sd:.{digits}f}"


def _present(values, candidates) -> list[float]:
    return [c for c in candidates if any(math.isclose(v, c) for v in values)]


def _pf(ok: bool | None) -> str:
    return "n/a" if ok is None else ("**PASS**" if ok else "**MISS**")


# ------------------------------------------------------------------ report

@dataclass(frozen=True)
class _Grid:
    """What a sweep covered: its rows and the speeds, k values, lanes and meshes they span."""

    rows: list[dict]
    threshold: float
    speeds: list[float]
    ks: list[float]
    lanes: list[int]
    meshes: list[str]
    side_rows: list[dict]
    """The rows with side-view metrics (the watched lane)."""
    calibration_meshes: str = ""
    """The mesh set the calibration was fitted on (its provenance); '' when it does not say."""


def _grid(rows: list[dict], threshold: float, calibration_meshes: str = "") -> _Grid:
    def distinct(column: str) -> list:
        return sorted({r[column] for r in rows})

    return _Grid(rows, threshold, distinct("speed_fpm"), distinct("k"), distinct("lane"), distinct("mesh"),
                 [r for r in rows if math.isfinite(r["nmdm"])], calibration_meshes)


def build(out: Path, meta: dict | None = None, docs: Path | None = None,
          calibration: Calibration | None = None) -> Path:
    """Write out/results.md and out/*.png from out/runs.csv; with ``docs`` also docs/results.md + docs/results/.

    ``calibration``: the one the sweep ran with (its threshold, cuts and, from its provenance, the mesh set it
    was fitted on); None = the resolved one (woody_common.calibration.resolve_calibration)."""
    out = Path(out)
    calibration = calibration or resolved_calibration()
    rows = read_runs(out / runs_csv.FILE_NAME)
    grid = _grid(_paper_rows(rows), calibration.phi_threshold,
                 str(calibration.provenance.get("calibration_meshes", "")))
    meta = meta or {}
    _plots(grid.rows, out, grid.speeds, grid.ks, grid.lanes, grid.threshold)
    lines = _summary_lines(grid, meta) + _throughput_lines(meta)
    checks: list[tuple[str, bool | None, str]] = []
    for section in (_side_view, _top_view, _lane_table, _classification):
        section_lines, section_checks = section(grid)
        lines += section_lines
        checks += section_checks
    set_lines, set_checks = evaluation.report(grid.rows, grid.threshold)
    lines += set_lines + _line_grade(rows, calibrated_rules(calibration), calibrated_range(calibration),
                                    calibration.provenance)
    lines += _targets_and_plots(checks + set_checks)
    text = "\n".join(lines) + "\n"
    md = out / "results.md"
    md.write_text(text.replace("{prefix}", ""))
    if docs is not None:
        _write_docs(out, Path(docs), text)
    return md


def _summary_lines(grid: _Grid, meta: dict) -> list[str]:
    """Title, what the sweep covered and the command lines that produced it."""
    rows, meshes = grid.rows, grid.meshes
    masses = sorted({r["mass"] for r in rows if math.isfinite(r["mass"])})
    L = ["# Reproducing the paper: drop-test sweep results\n"]
    n_ref = sum(evaluation.mesh_set(m) == evaluation.SET_REFERENCE for m in meshes)
    L.append(f"{len(meshes)} meshes ({n_ref} reference (real), {len(meshes) - n_ref} generated) × {len(grid.ks)} k × "
             f"{len(grid.speeds)} speeds × {len(grid.lanes)} lanes = "
             f"{len(rows)} fillet rows ({sum(r['status'] == 'scored' for r in rows)} with a scored Φ, "
             f"{len(grid.side_rows)} with side-view metrics). Total mass M = "
             f"{', '.join(f'{m:g}' for m in masses)} kg; Φ threshold {grid.threshold:g} "
             "(from the calibration, `woody calibrate`).\n")
    invocations = meta.get("invocations", [])
    if invocations:
        L.append("Command line(s) that produced `runs.csv` (wall time on this machine):\n")
        for inv in invocations:
            L.append(f"    {inv['command']}    # {inv['evaluations']} evaluations in {inv['wall_s'] / 60:.1f} min, "
                     f"{inv['jobs']} jobs on {inv['cores']} cores, finished {inv['finished']}")
        L.append("")
    return L


def _throughput_lines(meta: dict) -> list[str]:
    """Evaluations per minute and the projected wall time of the paper's full grid."""
    L = ["## Throughput\n"]
    if not meta.get("wall_s"):
        return L + ["- no timing recorded (runs.csv was not produced by `woody sweep` here)\n"]
    rate = meta["evaluations"] / meta["wall_s"] * 60.0
    hours = FULL_GRID_EVALS / rate / 60.0
    ok = rate >= GOAL_EVALS_PER_MIN
    L.append(f"- {meta['evaluations']} fillet evaluations in {meta['wall_s'] / 60:.1f} min wall = "
             f"**{rate:.0f} evaluations/min** on {meta['invocations'][-1]['cores']} cores "
             f"(one evaluation = one fillet in one lane of one run).")
    L.append(f"- Projection for the paper's full grid, 1,000 meshes × 6 k × 2 speeds × 3 lanes = "
             f"{FULL_GRID_EVALS:,} evaluations: **{hours:.1f} h** (goal < 4 h, i.e. ≥ "
             f"{GOAL_EVALS_PER_MIN:.0f}/min): {_pf(ok)}. (The side-view k = 10, 200, 400 runs are extra; "
             "the projection counts the top-down grid as the paper states it.)\n")
    return L


def _section_head(title: str, note: str, columns: list[str]) -> list[str]:
    """A report section's heading, its one-line note and the head of its table."""
    return [title + "\n", note + "\n", "| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]


def _side_view(grid: _Grid) -> tuple[list[str], list]:
    """The side-view table beside the paper's, the biological reference and the side-view checks."""
    L = _section_head("## Side view, centre lane (paper Table sv_results)",
                      "Project: mean ± sd over meshes of the watched (centre) lane; "
                      "paper: simulated digital twin, M = 100.",
                      ["FPM", "k", "n", "NMDM", "paper", "MDM (px)", "paper", "BE", "paper"])
    side_rows, ks = grid.side_rows, grid.ks
    side_means: dict[tuple[float, float], float] = {}
    for speed in grid.speeds:
        for k in _present(ks, sorted(set(ks) | set(PAPER_SIDE.get(speed, {})))):
            nm = mean_sd(_select(side_rows, speed, k, column="nmdm"))
            md = mean_sd(_select(side_rows, speed, k, column="mdm"))
            be = mean_sd(_select(side_rows, speed, k, column="be"))
            side_means[(speed, k)] = nm[0]
            paper = PAPER_SIDE.get(speed, {}).get(k)
            ps = ("—", "—", "—") if paper is None else (f"{paper[0]:.3f}", f"{paper[1]:.1f}", f"{paper[2]:.1f}")
            L.append(f"| {speed:g} | {k:g} | {nm[2]} | {_fmt(*nm, 3)} | {ps[0]} | {_fmt(*md, 1)} | {ps[1]} | "
                     f"{_fmt(*be, 1)} | {ps[2]} |")
    L.append("\nBiological ground truth (Yoon et al., averaged over 10–100 FPM), for reference:\n")
    L.append("| condition | NMDM | MDM | BE |")
    L.append("|---|---|---|---|")
    for cond, a, b, c in PAPER_BIOLOGICAL:
        L.append(f"| {cond} | {a} | {b} | {c} |")
    L.append("")
    return L, _side_checks(ks, side_means)


def _side_checks(ks: list[float], side_means: dict[tuple[float, float], float]) -> list:
    """NMDM rises with k, ΔNMDM and NMDM(k=0) within their bands, and rises with speed."""
    checks = []
    s100 = [(k, side_means[(100.0, k)]) for k in ks
            if (100.0, k) in side_means and math.isfinite(side_means[(100.0, k)])]
    if len(s100) >= 2:
        vals = [v for _, v in s100]
        ok = all(b > a for a, b in zip(vals, vals[1:]))
        checks.append(("side 100 FPM: NMDM rises monotonically with k", ok,
                       ", ".join(f"k={k:g}: {v:.3f}" for k, v in s100)))
    n0, n100 = side_means.get((100.0, 0.0), math.nan), side_means.get((100.0, 100.0), math.nan)
    if math.isfinite(n0) and math.isfinite(n100):
        d = n100 - n0
        checks.append((f"side 100 FPM: ΔNMDM(k=100 − k=0) within {DELTA_NMDM_RANGE[0]}–{DELTA_NMDM_RANGE[1]}",
                       DELTA_NMDM_RANGE[0] <= d <= DELTA_NMDM_RANGE[1],
                       f"{n100:.3f} − {n0:.3f} = {d:.3f} (paper {PAPER_DELTA_NMDM}, physical ≈ {PHYSICAL_DELTA_NMDM})"))
    if math.isfinite(n0):
        checks.append((f"side 100 FPM: NMDM(k=0) within {NMDM_NORMAL_RANGE[0]}–{NMDM_NORMAL_RANGE[1]}",
                       NMDM_NORMAL_RANGE[0] <= n0 <= NMDM_NORMAL_RANGE[1], f"{n0:.3f} (paper 0.520)"))
    n0_130 = side_means.get((130.0, 0.0), math.nan)
    if math.isfinite(n0) and math.isfinite(n0_130):
        checks.append(("side: NMDM(k=0) at 130 FPM > at 100 FPM", n0_130 > n0,
                       f"{n0_130:.3f} vs {n0:.3f} (paper 0.675 vs 0.520)"))
    return checks


def _top_view(grid: _Grid) -> tuple[list[str], list]:
    """The top-view Φ table beside the paper's and the top-view checks."""
    L = _section_head("## Top view, all lanes (paper Table tdv_results)",
                      "Project: mean ± sd over meshes × lanes of the scored fillets; paper: 1,000 meshes, M = 100.",
                      ["FPM", "k", "n", "Φ", "paper Φ", "Hu term", "paper", "Sol. term", "paper"])
    rows, ks = grid.rows, grid.ks
    scored = [r for r in rows if r["status"] == "scored"]
    top_means: dict[tuple[float, float], float] = {}
    for speed in grid.speeds:
        for k in _present(ks, sorted(PAPER_TOP.get(speed, {}) or ks)):
            phi = mean_sd(_select(rows, speed, k))
            hu = mean_sd(_select(scored, speed, k, column="hu_term"))
            so = mean_sd(_select(scored, speed, k, column="solidity_term"))
            top_means[(speed, k)] = phi[0]
            paper = PAPER_TOP.get(speed, {}).get(k)
            pp = ("—",) * 3 if paper is None else (f"{paper[0]:.2f} ± {paper[1]:.2f}", f"{paper[2]:.3f}",
                                                    f"{paper[3]:.3f}")
            L.append(f"| {speed:g} | {k:g} | {phi[2]} | {_fmt(*phi, 2)} | {pp[0]} | {hu[0]:.3f} | {pp[1]} | "
                     f"{so[0]:.4f} | {pp[2]} |")
    L.append("")
    top_k = [k for k in ks if k in PAPER_TOP.get(100.0, {})]
    return L, _top_checks(grid.speeds, top_k, top_means) + physics_checks(rows, grid.side_rows)


def _top_checks(speeds: list[float], top_k: list[float], top_means: dict[tuple[float, float], float]) -> list:
    """Φ falls with k, the k = 0 / k = 100 ratio, and every class lower at 130 than at 100 FPM."""
    checks = []
    for speed in speeds:
        seq = [(k, top_means.get((speed, k), math.nan)) for k in top_k]
        seq = [(k, v) for k, v in seq if math.isfinite(v)]
        if len(seq) >= 2:
            vals = [v for _, v in seq]
            checks.append((f"top {speed:g} FPM: Φ falls monotonically with k",
                           all(b < a for a, b in zip(vals, vals[1:])),
                           ", ".join(f"k={k:g}: {v:.2f}" for k, v in seq)))
    p0, p100 = top_means.get((100.0, 0.0), math.nan), top_means.get((100.0, 100.0), math.nan)
    if math.isfinite(p0) and math.isfinite(p100):
        checks.append((f"top 100 FPM: Φ(k=0)/Φ(k=100) ≥ {PHI_RATIO_MIN}", p0 / p100 >= PHI_RATIO_MIN,
                       f"{p0:.2f} / {p100:.2f} = {p0 / p100:.2f} (paper 3.5)"))
    if 100.0 in speeds and 130.0 in speeds:
        pairs = [(k, top_means.get((100.0, k), math.nan), top_means.get((130.0, k), math.nan)) for k in top_k]
        pairs = [p for p in pairs if math.isfinite(p[1]) and math.isfinite(p[2])]
        if pairs:
            checks.append(("top: every class scores lower at 130 than at 100 FPM", all(b < a for _, a, b in pairs),
                           ", ".join(f"k={k:g}: {b:.2f} vs {a:.2f}" for k, a, b in pairs)))
    return checks


def _lane_table(grid: _Grid) -> tuple[list[str], list]:
    """Normal vs severe Φ per lane beside the paper's, and whether their ±1 sd bands separate."""
    L = _section_head("## Lanes (paper Table lane_analysis)",
                      "Normal = k 0, severe = k 100; project mean ± sd over meshes per lane (lane 1 = centre).",
                      ["FPM", "lane", "normal Φ", "paper", "severe Φ", "paper", "ΔΦ", "paper ΔΦ"])
    rows, checks = grid.rows, []
    for speed in grid.speeds:
        for lane in grid.lanes:
            normal, severe = _select(rows, speed, NORMAL_K, lane), _select(rows, speed, SEVERE_K, lane)
            nrm, sev = mean_sd(normal), mean_sd(severe)
            paper = PAPER_LANES.get(lane) if math.isclose(speed, 100.0) else None
            pp = ("—",) * 3 if paper is None else (f"{paper[0]:.2f} ± {paper[1]:.2f}",
                                                    f"{paper[2]:.2f} ± {paper[3]:.2f}", f"{paper[4]:.2f}")
            L.append(f"| {speed:g} | {lane} | {_fmt(*nrm, 2)} | {pp[0]} | {_fmt(*sev, 2)} | {pp[1]} | "
                     f"{nrm[0] - sev[0]:.2f} | {pp[2]} |")
            if nrm[2] and sev[2]:
                sep = nrm[0] - nrm[1] > sev[0] + sev[1]
                checks.append((f"lanes {speed:g} FPM, lane {lane}: normal vs severe separate (±1 sd bands disjoint)",
                               sep, f"normal {nrm[0]:.2f} − {nrm[1]:.2f} = {nrm[0] - nrm[1]:.2f} vs severe "
                                    f"{sev[0]:.2f} + {sev[1]:.2f} = {sev[0] + sev[1]:.2f}; ranges normal "
                                    f"[{min(normal):.2f}, {max(normal):.2f}], severe "
                                    f"[{min(severe):.2f}, {max(severe):.2f}]"))
    L.append("")
    return L, checks


def _classification(grid: _Grid) -> tuple[list[str], list]:
    """Accuracy, ROC AUC and the best threshold per lane and pooled, at the calibrated threshold."""
    rows, threshold, checks = grid.rows, grid.threshold, []
    L = [f"## Classification per fillet: normal (k = 0) vs severe (k = 100) at Φ threshold {threshold:g}\n",
         _heldout_note(grid.meshes, grid.calibration_meshes),
         "Every lane counts here, pooled over all mesh sets; lanes of one run are not independent, see the "
         "per-set section below for one vote per run with confidence intervals.\n",
         "| FPM | lane | accuracy | right / total | ROC AUC | best possible threshold here (bal. acc.) |",
         "|---|---|---|---|---|---|"]
    for speed in grid.speeds:
        for lane in list(grid.lanes) + [None]:
            nrm, sev = _select(rows, speed, NORMAL_K, lane), _select(rows, speed, SEVERE_K, lane)
            if nrm.size == 0 or sev.size == 0:
                continue
            acc, right, total = accuracy(nrm, sev, threshold)
            auc = roc(nrm, sev)[2]
            bt, bacc = best_threshold(nrm, sev)
            L.append(f"| {speed:g} | {'all' if lane is None else lane} | {acc * 100:.1f} % | {right} / {total} | "
                     f"{auc:.3f} | {bt:.2f} ({bacc * 100:.1f} %) |")
            if lane is not None:
                checks.append((f"accuracy {speed:g} FPM lane {lane} ≥ {ACCURACY_MIN * 100:.0f} %", acc >= ACCURACY_MIN,
                               f"{acc * 100:.1f} % ({right}/{total}), AUC {auc:.3f}"))
    L.append("")
    return L, checks


def _paper_rows(rows: list[dict]) -> list[dict]:
    """The rows the paper's tables are about: the tidy line at the paper's speeds (any others only in the line
    grade's section)."""
    paper = [r for r in rows if (r.get("condition") or TIDY) == TIDY and r["speed_fpm"] in PAPER_SPEEDS_FPM]
    return paper or [r for r in rows if (r.get("condition") or TIDY) == TIDY]


def _line_grade(rows: list[dict], rules, fitted, provenance: dict) -> list[str]:
    """The line's grade (line_phi against the calibrated cuts) per condition and speed, one vote per run; a run
    measured outside the calibration's fitted range is unscored (diverted), as the grader leaves it."""
    runs = line_grade.graded_runs(rows, rules, fitted)
    if not runs:
        return []
    L = ["## The line's grade on a messy line\n",
         "The grade the line uses: `line_phi` against the calibrated cuts, which follow each fillet's measured speed, "
         "leading end, turn and length (`docs/shape-score.md`). Cuts fitted on "
         f"`{provenance.get('calibration_meshes', '?')}` (conditions {provenance.get('line_conditions', '?')}, "
         f"{provenance.get('line_speeds_fpm', '?')} FPM); every mesh here is disjoint from them. One vote per run "
         "(median over its lanes); normal k = 0 vs severe k = 100; three classes normal k = 0 / moderate "
         "0 < k < 40 / severe k ≥ 40. 95 % Wilson intervals. A run measured outside the conditions the cuts were "
         f"fitted on ({_range_text(fitted)}) is unscored and diverted, as the grader leaves such a fillet.\n",
         "| condition | FPM | meshes | normal vs severe | severe graded normal | unscored (outside the calibration) | "
         "AUC | three classes |",
         "|---|---|---|---|---|---|---|---|"]
    for condition in dict.fromkeys(r.condition for r in runs):
        for speed in sorted({r.speed_fpm for r in runs if r.condition == condition}):
            summary = line_grade.summarise([r for r in runs if r.condition == condition and r.speed_fpm == speed])
            L.append(f"| {condition} | {speed:g} | {summary.meshes} | {share_text(summary.right, summary.total)} | "
                     f"{summary.severe_passed} of {summary.severe_total} | {summary.unscored} | {summary.auc:.3f} | "
                     f"{share_text(summary.grade_right, summary.grade_total)} |")
    for condition in dict.fromkeys(r.condition for r in runs):
        L += _confusion(condition, line_grade.summarise([r for r in runs if r.condition == condition]))
    return L + _grade_by_k([r for r in runs if r.condition == TIDY])


def _grade_by_k(runs: list) -> list[str]:
    """The tidy line's grade stiffness by stiffness: where the three classes' scores overlap."""
    if not runs:
        return []
    L = ["Three classes, tidy line, by stiffness (runs graded each way: where the classes' scores overlap):\n",
         "| k | truth | " + " | ".join(line_grade.GRADES) + " | right |", "|---|---|---|---|---|---|"]
    for k in sorted({r.k for r in runs}):
        of_k = [r for r in runs if r.k == k]
        truth = line_grade.true_grade(k)
        counts = [sum(r.grade == g for r in of_k) for g in line_grade.GRADES]
        right = counts[line_grade.GRADES.index(truth)]
        L.append(f"| {k:g} | {truth} | " + " | ".join(map(str, counts)) + f" | {share_text(right, len(of_k))} |")
    return L + [""]


def _range_text(fitted) -> str:
    return (f"{fitted.speed_min_mps:.2f}-{fitted.speed_max_mps:.2f} m/s, turned up to {fitted.turn_max_deg:.0f} deg, "
            f"bodies {fitted.length_min_m:.3f}-{fitted.length_max_m:.3f} m")


def _confusion(condition: str, summary) -> list[str]:
    """The three-class confusion matrix of a condition, all its speeds."""
    if not summary.grade_total:
        return []
    L = ["", f"Three classes, {condition} line, all speeds (rows: truth, columns: graded):\n",
         "| truth \\ graded | " + " | ".join(line_grade.GRADES) + " |", "|---|---|---|---|"]
    for truth in line_grade.GRADES:
        L.append(f"| {truth} | " + " | ".join(str(summary.confusion.get((truth, g), 0)) for g in line_grade.GRADES)
                 + " |")
    return L + [""]


def _targets_and_plots(checks: list) -> list[str]:
    """The PASS / MISS table of every check, the plots and the marker a hand-written discussion follows."""
    L = ["## Targets\n", "| target | result | numbers |", "|---|---|---|"]
    for name, ok, detail in checks:
        L.append(f"| {name} | {_pf(ok)} | {detail} |")
    n_pass = sum(1 for _, ok, _ in checks if ok)
    L.append(f"\n{n_pass} of {len(checks)} targets pass.\n")
    L.append("## Plots\n")
    for name in PLOTS:
        L.append(f"![{name}]({{prefix}}{name})")
    return L + ["", "<!-- discussion -->"]


def _write_docs(out: Path, docs: Path, text: str) -> None:
    """docs/results.md (keeping its hand-written discussion below the marker), docs/results/*.png and the
    raw docs/results/runs.csv the figures come from."""
    (docs / "results").mkdir(parents=True, exist_ok=True)
    for name in (*PLOTS, runs_csv.FILE_NAME):
        if (out / name).exists():
            shutil.copy(out / name, docs / "results" / name)
    target = docs / "results.md"
    discussion = ""
    if target.exists():
        old = target.read_text()
        if "<!-- discussion -->" in old:
            discussion = old.split("<!-- discussion -->", 1)[1].lstrip("\n")
    target.write_text(text.replace("{prefix}", "results/") + discussion)


def _heldout_note(meshes: list[str], calibration_meshes: str) -> str:
    """Whether the report's meshes are held out from the mesh set the calibration was fitted on."""
    if not calibration_meshes:
        return ""
    try:
        cal = {m.name for m in load_mesh_set(calibration_meshes)[0]}
    except Exception:  # noqa: BLE001 - the note is informative only
        return ""
    overlap = sorted(set(meshes) & cal)
    if overlap:
        return (f"The threshold was chosen by `woody calibrate` on `{calibration_meshes}`; {len(overlap)} of these "
                f"meshes are in that calibration set, so this is **not** fully held out.\n")
    return (f"The threshold was chosen by `woody calibrate` on the calibration set `{calibration_meshes}`; "
            f"none of the {len(meshes)} meshes here is in it (held out).\n")


# ------------------------------------------------------------------ plots

_SPEED_COLORS = {100.0: "tab:blue", 130.0: "tab:orange"}


def _plots(rows, out: Path, speeds, ks, lanes, threshold: float) -> None:
    """The four PLOTS of the report, written into ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    top_k = [k for k in ks if k <= 100.0] or ks
    for name, draw in (("phi_vs_k.png", lambda: _plot_phi_vs_k(plt, rows, speeds, top_k, threshold)),
                       ("nmdm_vs_k.png", lambda: _plot_nmdm_vs_k(plt, rows, speeds)),
                       ("phi_per_lane.png", lambda: _plot_phi_per_lane(plt, rows, speeds, top_k, lanes)),
                       ("roc.png", lambda: _plot_roc(plt, rows, speeds, lanes))):
        fig = draw()
        fig.tight_layout()
        fig.savefig(out / name, dpi=110)
        plt.close(fig)


def _label(ax, xlabel: str, ylabel: str, title: str, legend_fontsize: int) -> None:
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=legend_fontsize)


def _plot_phi_vs_k(plt, rows, speeds, top_k, threshold: float):
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for speed in speeds:
        _plot_beside_paper(ax, rows, speed, top_k, "phi", PAPER_TOP.get(speed), _SPEED_COLORS.get(speed))
    ax.axhline(threshold, color="grey", lw=0.8, ls=":", label=f"threshold {threshold:g}")
    _label(ax, "hinge stiffness k (N m/rad)", "shape score Φ", "Top view: Φ vs k (mean ± sd over meshes and lanes)", 8)
    return fig


def _plot_nmdm_vs_k(plt, rows, speeds):
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    side = [r for r in rows if math.isfinite(r["nmdm"])]
    for speed in speeds:
        sk = sorted({r["k"] for r in side if math.isclose(r["speed_fpm"], speed)})
        _plot_beside_paper(ax, side, speed, sk, "nmdm", PAPER_SIDE.get(speed), _SPEED_COLORS.get(speed))
    ax.axhspan(0.31, 0.51, color="green", alpha=0.08, label="physical normal 0.41 ± 0.10")
    ax.axhspan(0.58, 0.74, color="red", alpha=0.08, label="physical severe 0.66 ± 0.08")
    ax.set_xscale("symlog", linthresh=10)
    _label(ax, "hinge stiffness k (N m/rad, symlog)", "NMDM", "Side view (centre lane): NMDM vs k", 7)
    return fig


def _plot_phi_per_lane(plt, rows, speeds, top_k, lanes):
    fig, axes = plt.subplots(1, max(1, len(speeds)), figsize=(5.0 * max(1, len(speeds)), 3.8), squeeze=False)
    for ax, speed in zip(axes[0], speeds):
        for lane in lanes:
            stats = [mean_sd(_select(rows, speed, k, lane)) for k in top_k]
            ax.errorbar(np.array(top_k) + (lane - 1) * 1.2, [s[0] for s in stats], yerr=[s[1] for s in stats],
                        marker="o", capsize=2, label=f"lane {lane}")
        _label(ax, "k", "Φ", f"Φ per lane, {speed:g} FPM", 8)
    return fig


def _plot_roc(plt, rows, speeds, lanes):
    fig, ax = plt.subplots(figsize=(4.6, 4.2))
    for speed in speeds:
        for lane in [None] + list(lanes):
            nrm, sev = _select(rows, speed, NORMAL_K, lane), _select(rows, speed, SEVERE_K, lane)
            if nrm.size == 0 or sev.size == 0:
                continue
            fpr, tpr, auc = roc(nrm, sev)
            if lane is None:
                ax.plot(fpr, tpr, color=_SPEED_COLORS.get(speed), lw=2,
                        label=f"{speed:g} FPM all lanes, AUC {auc:.3f}")
            else:
                ax.plot(fpr, tpr, color=_SPEED_COLORS.get(speed), lw=0.8, alpha=0.5, ls=":")
    ax.plot([0, 1], [0, 1], color="grey", lw=0.5)
    ax.set_xlabel("false-positive rate (normal called woody)")
    ax.set_ylabel("true-positive rate (severe called woody)")
    ax.set_title("ROC of Φ: normal k=0 vs severe k=100\n(dotted: single lanes)", fontsize=9)
    if ax.get_legend_handles_labels()[0]:  # no curve when the sweep lacks k = 0 or k = 100
        ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3)
    return fig
