"""`woody meshes stats SPEC [SPEC...]`: shape descriptors per mesh and per set, to compare mesh sets."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from woody_sim.mesh_stats import DESCRIPTOR_NAMES, FOOTPRINT_HEIGHT_M, Descriptors, describe, summarize
from woody_sim.meshes import checked_mesh_set

_COLUMNS = {  # descriptor -> (column title, scale, format)
    "aspect_ratio": ("aspect", 1.0, "{:.2f}"),
    "solidity": ("solidity", 1.0, "{:.3f}"),
    "rim_roughness": ("rim", 1.0, "{:.3f}"),
    "width_10": ("w10", 1.0, "{:.2f}"),
    "width_25": ("w25", 1.0, "{:.2f}"),
    "width_50": ("w50", 1.0, "{:.2f}"),
    "width_75": ("w75", 1.0, "{:.2f}"),
    "width_90": ("w90", 1.0, "{:.2f}"),
    "thickness_m": ("thick_mm", 1000.0, "{:.1f}"),
    "fullness": ("full", 1.0, "{:.2f}"),
    "area_m2": ("area_cm2", 1e4, "{:.0f}"),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="meshes_command", required=True, metavar="ACTION")
    stats = sub.add_parser("stats", help="shape descriptors per mesh and per set (docs/physics.md, Generated fillets)")
    stats.add_argument("specs", nargs="+", metavar="SPEC",
                       help="a mesh set as `woody run --meshes` takes it: builtin, generated:N[:SEED], a folder, "
                            "a mesh file, or a comma-separated mix; each SPEC is summarised as one set")
    stats.add_argument("--json", default=None, metavar="FILE", help="also write every figure to this JSON file")
    stats.add_argument("--height-threshold", type=float, default=FOOTPRINT_HEIGHT_M, metavar="M",
                       help=f"footprint = heights above this (m); default {FOOTPRINT_HEIGHT_M} (the silhouette), "
                            "0.005 gives the segmenter's view")


def _row(label: str, values: dict[str, float]) -> str:
    cells = [_COLUMNS[k][2].format(values[k] * _COLUMNS[k][1]) for k in DESCRIPTOR_NAMES]
    return f"{label:<22}" + "".join(f"{c:>10}" for c in cells)


def _set_lines(spec: str, meshes: list[Descriptors]) -> list[str]:
    """The table of one set: a row per mesh, then mean, sd, min and max."""
    header = f"{'mesh':<22}" + "".join(f"{_COLUMNS[k][0]:>10}" for k in DESCRIPTOR_NAMES)
    lines = [f"set {spec}: {len(meshes)} meshes", header]
    lines += [_row(d.name, d.values()) for d in meshes]
    summary = summarize(meshes)
    for stat in ("mean", "sd", "min", "max"):
        lines.append(_row(f"  {stat}", {k: summary[k][stat] for k in DESCRIPTOR_NAMES}))
    return lines


def _describe_spec(spec: str, threshold: float) -> list[Descriptors]:
    fillets, notes = checked_mesh_set(spec)
    for note in notes:
        print(f"woody meshes stats: {note}", file=sys.stderr)
    return [describe(fillet, threshold) for fillet in fillets]


def run(args: argparse.Namespace) -> int:
    if not 0.0 <= args.height_threshold < 0.02:
        print(f"woody meshes stats: --height-threshold must be in [0, 0.02) m, got {args.height_threshold}",
              file=sys.stderr)
        return 2
    report = {"height_threshold_m": args.height_threshold, "sets": []}
    for spec in args.specs:
        try:
            meshes = _describe_spec(spec, args.height_threshold)
        except ValueError as exc:
            print(f"woody meshes stats: {exc}", file=sys.stderr)
            return 2
        print("\n".join(_set_lines(spec, meshes)) + "\n")
        report["sets"].append({"spec": spec, "meshes": [{"name": d.name, **d.values()} for d in meshes],
                               "summary": summarize(meshes)})
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=2) + "\n")
        print(f"descriptors: {args.json}")
    return 0
