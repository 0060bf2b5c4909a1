"""Labelled frames of the line, with the truth per pixel, for training and testing other graders (`woody dataset`).

A data set is a grid of runs like `woody sweep`'s (meshes x k x speeds x
conditions, the same :class:`~woody_experiments.experiment.RunSpec`), each
simulated by :func:`~woody_experiments.experiment.evaluate_run` with its
top-frame hook: every frame the top camera delivers from the fillets' spawn to
the close of the last lane's evaluation window, with the renderer's instance
image (which fillet each pixel shows). A worker writes one run's files under
``runs/<run>/`` and ``sequences/<run>/`` and returns the run's record, which it
also keeps as ``runs/<run>/run.json`` (written last: a run without it is
redone). The client alone writes the index files from the records of every
run, so an interrupted command resumes where it stopped, and a rerun writes
the same bytes (no clock or host in any file).

Layout of a data set folder::

    README.md                      the datasheet: what, how made, the command, counts, licences
    dataset.json                   the grid and the seed (a rerun into the folder must match)
    splits.json                    mesh -> split: no mesh is in two splits
    fillets.csv                    one row per fillet: its truth (verdicts.csv's columns) and woody's own grade
    annotations/top_<split>.json   COCO instance segmentation (RLE), one file per split
    annotations/side_<split>.json  the same for the side camera (with --side)
    runs/<run>/camera_info/top.yaml     the camera (ROS camera_calibration YAML), side.yaml with --side
    runs/<run>/top/color/NNNN.png       rgb, and top/depth/NNNN.png: 16-bit depth in millimetres, 0 = no return
    runs/<run>/side/color/NNNN.png      with --side
    sequences/<run>/lane<L>/            one fillet from approach to the end of its window: color/, depth/,
                                        mask/ crops (one size per fillet) and sequence.json (labels, frames)

The lanes of a run are the sweep's: one simulated chain whose pose is copied
into every lane, seen in each lane's own perspective (experiment module doc).
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml
from pycocotools import mask as coco_mask

from woody_common.line import fpm_to_mps
from woody_experiments.experiment import RunSpec, TopFrame, evaluate_run, run_geometry
from woody_experiments.line_grade import GRADES, true_grade
from woody_sim.line_geometry import PinholeCamera
from woody_sim.meshes import BUILTIN_DIR, FilletMesh
from woody_sim.rendering import camera_info_fields

WOODY_K = 50.0
"""Stiffness from which a fillet's reject truth is woody: the rule of `woody run`'s verdicts.csv."""
SPLITS = ("train", "val", "test")
SPLIT_FRACTIONS = (0.7, 0.15, 0.15)
CATEGORIES = [{"id": i + 1, "name": grade, "supercategory": "fillet"} for i, grade in enumerate(GRADES)]
"""COCO categories: the three-class grade of the fillet's true stiffness."""
DEPTH_UNIT_M = 0.001
"""Depth PNGs hold millimetres (uint16); 0 is a pixel without a return."""
CROP_MARGIN_PX = 8
"""Border around a fillet's largest outline in its sequence crops."""
RUN_RECORD = "run.json"
FILLET_COLUMNS = ["run", "split", "mesh", "lane", "k", "truth", "true_grade", "speed_fpm", "speed_mps", "condition",
                  "yaw_deg", "leading_end", "lateral_offset_m", "scale", "frames", "window_frames", "verdict_status",
                  "line_phi", "phi"]
"""fillets.csv: the truth under verdicts.csv's names (mesh, lane, k, truth, true_grade, speed_fpm), the
placement, and what woody's own grader made of the fillet in the same run."""


# ---------------------------------------------------------------- the grid

def run_name(spec: RunSpec) -> str:
    """A file-safe, unique name of one run of the grid."""
    raw = f"{spec.mesh}_k{spec.k:g}_{spec.speed_fpm:g}fpm_{spec.condition}"
    return re.sub(r"[^A-Za-z0-9_.-]", "-", raw)


def split_meshes(names: Sequence[str], seed: int) -> dict[str, str]:
    """Mesh -> split, by mesh: each split gets whole meshes (``SPLIT_FRACTIONS``; val and test at least one mesh
    each once there are three), drawn by ``seed``."""
    order = sorted(set(names))
    np.random.default_rng(seed).shuffle(order)
    n = len(order)
    held = [max(1, round(f * n)) if n >= 3 else 0 for f in SPLIT_FRACTIONS[1:]]
    if n == 2:
        held = [0, 1]
    n_train = n - sum(held)
    bounds = np.cumsum([n_train, *held])
    return {name: SPLITS[int(np.searchsorted(bounds, i, side="right"))] for i, name in enumerate(order)}


# ---------------------------------------------------------------- one run, on a worker

@dataclass(frozen=True)
class RunOptions:
    """What every run of a data set writes, besides its spec."""

    out: str
    """The data set folder (workers must see it at this path)."""
    side: bool = False
    """Also write the side camera's frames and masks (watched lane)."""


def render_run(spec: RunSpec, mesh: FilletMesh, options: RunOptions) -> list[dict]:
    """Simulate one run, write its frames, masks and sequences, and return [its record] (also ``run.json``)."""
    name = run_name(spec)
    root = Path(options.out)
    run_dir = root / "runs" / name
    writer = _FrameWriter(run_dir, options.side)
    rows = evaluate_run(spec, mesh, on_top_frame=writer.add, side_frames=options.side)
    geometry = run_geometry(spec)
    _write_camera_info(run_dir / "camera_info" / "top.yaml", geometry.top_camera(), "top")
    if options.side:
        _write_camera_info(run_dir / "camera_info" / "side.yaml", geometry.side_camera(), "side")
    fillets = [_fillet(spec, name, row) for row in rows]
    for fillet in fillets:
        fillet["sequence"] = _write_sequence(root, run_dir, name, fillet, writer.records)
    record = {"run": name, "mesh": spec.mesh, "frames": writer.records, "side_frames": writer.side_records,
              "fillets": fillets}
    tmp = run_dir / (RUN_RECORD + ".tmp")
    tmp.write_text(json.dumps(record, sort_keys=True))
    tmp.replace(run_dir / RUN_RECORD)
    return [record]


class _FrameWriter:
    """Writes each delivered top frame (and side frame) and keeps its record, with the per-fillet masks as RLE."""

    def __init__(self, run_dir: Path, side: bool) -> None:
        self.run_dir, self.side = run_dir, side
        for sub in ("top/color", "top/depth", "camera_info") + (("side/color",) if side else ()):
            (run_dir / sub).mkdir(parents=True, exist_ok=True)
        self.records: list[dict] = []
        self.side_records: list[dict] = []

    def add(self, frame: TopFrame) -> None:
        index = len(self.records)
        color, depth = f"top/color/{index:04d}.png", f"top/depth/{index:04d}.png"
        _write_png(self.run_dir / color, cv2.cvtColor(frame.color, cv2.COLOR_RGB2BGR))
        _write_png(self.run_dir / depth, depth_png(frame.depth))
        self.records.append({"index": index, "stamp": round(frame.stamp, 6), "file": color, "depth_file": depth,
                             "width": int(frame.color.shape[1]), "height": int(frame.color.shape[0]),
                             "fillets": _instances(frame, frame.instances)})
        if self.side:
            self._add_side(frame, index)

    def _add_side(self, frame: TopFrame, index: int) -> None:
        color = f"side/color/{index:04d}.png"
        _write_png(self.run_dir / color, cv2.cvtColor(frame.side_color, cv2.COLOR_RGB2BGR))
        self.side_records.append({"index": index, "stamp": round(frame.stamp, 6), "file": color,
                                  "width": int(frame.side_color.shape[1]), "height": int(frame.side_color.shape[0]),
                                  "fillets": _instances(frame, frame.side_instances)})


def depth_png(depth_m: np.ndarray) -> np.ndarray:
    """Metres (NaN or inf: no return) as uint16 millimetres, 0 where there is no return."""
    mm = np.where(np.isfinite(depth_m), np.round(depth_m / DEPTH_UNIT_M), 0.0)
    return np.clip(mm, 0, np.iinfo(np.uint16).max).astype(np.uint16)


def encode_mask(mask: np.ndarray) -> dict:
    """A boolean mask as COCO compressed RLE (counts as text, for JSON)."""
    rle = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(s) for s in rle["size"]], "counts": rle["counts"].decode("ascii")}


def _instances(frame: TopFrame, image: np.ndarray) -> list[dict]:
    """One record per fillet seen in an instance image of the frame: its lane, mask (RLE), box, area, and where
    it is along the flow relative to the roller edge (world x = 0; m, + downstream)."""
    out = []
    for render_id, lane in frame.lanes.items():
        mask = image == render_id
        if not mask.any():
            continue
        v, u = np.nonzero(mask)
        x = frame.poses[render_id][:, 0]
        out.append({"lane": lane, "area": int(mask.sum()), "segmentation": encode_mask(mask),
                    "bbox": [int(u.min()), int(v.min()), int(u.max() - u.min() + 1), int(v.max() - v.min() + 1)],
                    "centre_x_m": round(float(x.mean()), 5), "front_x_m": round(float(x.max()), 5)})
    return out


def _write_png(path: Path, image: np.ndarray) -> None:
    if not cv2.imwrite(str(path), image):
        raise OSError(f"cannot write {path}")


def _write_camera_info(path: Path, camera: PinholeCamera, name: str) -> None:
    """The camera as ROS's camera_calibration YAML (what camera_info_manager reads)."""
    info = camera_info_fields(camera)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump({
        "image_width": info["width"], "image_height": info["height"], "camera_name": name,
        "camera_matrix": {"rows": 3, "cols": 3, "data": info["k"]},
        "distortion_model": info["distortion_model"],
        "distortion_coefficients": {"rows": 1, "cols": 5, "data": info["d"]},
        "rectification_matrix": {"rows": 3, "cols": 3, "data": info["r"]},
        "projection_matrix": {"rows": 3, "cols": 4, "data": info["p"]},
    }, sort_keys=False))


def _fillet(spec: RunSpec, name: str, row: dict) -> dict:
    """One lane's fillet: its truth and placement, and what woody's grader made of it."""
    placement = spec.placement
    return {"run": name, "mesh": spec.mesh, "lane": int(row["lane"]), "k": spec.k,
            "truth": "woody" if spec.k >= WOODY_K else "normal", "true_grade": true_grade(spec.k),
            "speed_fpm": spec.speed_fpm, "speed_mps": round(fpm_to_mps(spec.speed_fpm), 6),
            "condition": spec.condition, "yaw_deg": round(float(row["yaw_deg"]), 4),
            "leading_end": "blunt" if placement.blunt_first else "narrow",
            "lateral_offset_m": round(float(placement.lateral_offset_m), 5), "scale": round(float(row["scale"]), 5),
            "verdict_status": row["status"], "line_phi": _rounded(row["line_phi"]), "phi": _rounded(row["phi"]),
            "reference_stamp": row.get("reference_stamp"), "window_stamps": row.get("window_stamps", [])}


def _rounded(value: float) -> float | None:
    return round(float(value), 5) if math.isfinite(value) else None


# ---------------------------------------------------------------- sequences

def _write_sequence(root: Path, run_dir: Path, run: str, fillet: dict, records: list[dict]) -> dict:
    """One fillet's crops from the first frame it is seen to the last frame of its evaluation window (or the
    last frame it is seen, if the grader scored none), one crop size for all, cut from the run's written
    frames; its counts."""
    lane = fillet["lane"]
    seen = [(r, next(f for f in r["fillets"] if f["lane"] == lane)) for r in records
            if any(f["lane"] == lane for f in r["fillets"])]
    window = {round(s, 6) for s in fillet["window_stamps"]}
    last = max((n for n, (r, _) in enumerate(seen) if r["stamp"] in window), default=len(seen) - 1)
    seen = seen[:last + 1]
    folder = root / "sequences" / run / f"lane{lane}"
    for sub in ("color", "depth", "mask"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    size = (max((i["bbox"][2] for _, i in seen), default=0) + 2 * CROP_MARGIN_PX,
            max((i["bbox"][3] for _, i in seen), default=0) + 2 * CROP_MARGIN_PX)
    entries = []
    for n, (record, instance) in enumerate(seen):
        u, v, w, h = instance["bbox"]
        u0, v0 = u + w // 2 - size[0] // 2, v + h // 2 - size[1] // 2
        name = f"{n:04d}.png"
        color = cv2.imread(str(run_dir / record["file"]), cv2.IMREAD_UNCHANGED)
        depth = cv2.imread(str(run_dir / record["depth_file"]), cv2.IMREAD_UNCHANGED)
        mask = coco_mask.decode(instance["segmentation"])
        _write_png(folder / "color" / name, _crop(color, u0, v0, size))
        _write_png(folder / "depth" / name, _crop(depth, u0, v0, size))
        _write_png(folder / "mask" / name, _crop(mask, u0, v0, size) * 255)
        entries.append({"file": name, "frame": record["index"], "stamp": record["stamp"],
                        "crop_origin_uv": [u0, v0], "in_window": record["stamp"] in window,
                        "centre_x_m": instance["centre_x_m"], "front_x_m": instance["front_x_m"]})
    labels = {c: fillet[c] for c in FILLET_COLUMNS if c in fillet}
    (folder / "sequence.json").write_text(json.dumps(
        {"labels": labels, "reference_stamp": fillet["reference_stamp"], "crop_size_wh": list(size),
         "frames": entries}, sort_keys=True, indent=1))
    return {"frames": len(entries), "window_frames": sum(e["in_window"] for e in entries)}


def _crop(image: np.ndarray, u0: int, v0: int, size: tuple[int, int]) -> np.ndarray:
    """``size`` (w, h) pixels of ``image`` from (u0, v0), 0 where the box leaves the image."""
    w, h = size
    out = np.zeros((h, w) + image.shape[2:], dtype=image.dtype)
    su, sv = max(u0, 0), max(v0, 0)
    eu, ev = min(u0 + w, image.shape[1]), min(v0 + h, image.shape[0])
    if eu > su and ev > sv:
        out[sv - v0:ev - v0, su - u0:eu - u0] = image[sv:ev, su:eu]
    return out


# ---------------------------------------------------------------- the index files, on the client

def finished_runs(root: Path) -> list[Path]:
    """The records of every finished run in a data set folder, in name order."""
    return sorted((root / "runs").glob(f"*/{RUN_RECORD}"))


def read_records(root: Path) -> dict[str, dict]:
    """Run name -> record of every finished run in a data set folder."""
    return {p.parent.name: json.loads(p.read_text()) for p in finished_runs(root)}


def coco_files(records: Sequence[dict], splits: dict[str, str], camera: str = "top") -> dict[str, dict]:
    """Split -> COCO instance-segmentation dict of ``camera``'s frames (runs in name order, frames in time)."""
    out = {s: {"info": {"description": f"woody {camera} camera, split {s}", "version": "1"}, "images": [],
               "annotations": [], "categories": CATEGORIES} for s in SPLITS}
    image_id = annotation_id = 0
    key = "frames" if camera == "top" else "side_frames"
    for record in sorted(records, key=lambda r: r["run"]):
        coco = out[splits[record["mesh"]]]
        truth = {f["lane"]: f for f in record["fillets"]}
        for frame in record[key]:
            image_id += 1
            coco["images"].append({"id": image_id, "file_name": f"runs/{record['run']}/{frame['file']}",
                                   "width": frame["width"], "height": frame["height"], "run": record["run"],
                                   "stamp": frame["stamp"], "depth_file": _depth_file(record["run"], frame),
                                   "camera_info": f"runs/{record['run']}/camera_info/{camera}.yaml"})
            for fillet in frame["fillets"]:
                annotation_id += 1
                coco["annotations"].append(_annotation(annotation_id, image_id, fillet, truth[fillet["lane"]]))
    return out


def _depth_file(run: str, frame: dict) -> str | None:
    return f"runs/{run}/{frame['depth_file']}" if "depth_file" in frame else None


def _annotation(annotation_id: int, image_id: int, instance: dict, fillet: dict) -> dict:
    attributes = {c: fillet[c] for c in FILLET_COLUMNS if c in fillet and c not in ("frames", "window_frames")}
    attributes.update(centre_x_m=instance["centre_x_m"], front_x_m=instance["front_x_m"])
    return {"id": annotation_id, "image_id": image_id, "category_id": GRADES.index(fillet["true_grade"]) + 1,
            "segmentation": instance["segmentation"], "area": instance["area"], "bbox": instance["bbox"],
            "iscrowd": 0, "attributes": attributes}


def fillet_rows(records: Sequence[dict], splits: dict[str, str]) -> list[dict]:
    """fillets.csv's rows: one per fillet, runs in name order, lanes in order."""
    rows = []
    for record in sorted(records, key=lambda r: r["run"]):
        for fillet in sorted(record["fillets"], key=lambda f: f["lane"]):
            rows.append({**{c: fillet.get(c) for c in FILLET_COLUMNS}, "split": splits[record["mesh"]],
                         "frames": fillet["sequence"]["frames"],
                         "window_frames": fillet["sequence"]["window_frames"]})
    return rows


def fillets_csv(rows: Sequence[dict]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=FILLET_COLUMNS, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({c: "" if row[c] is None else row[c] for c in FILLET_COLUMNS})
    return buffer.getvalue()


def mesh_licence(mesh: FilletMesh) -> str:
    """Where a mesh comes from and under which licence its renderings may be shared."""
    if mesh.source.startswith("generated:"):
        return f"generated by woody (seed {mesh.source.split(':', 1)[1]}); Apache-2.0, as woody"
    if Path(mesh.source).resolve().parent == BUILTIN_DIR:
        return ("the paper's Synthetic-Chicken-Fillets data set (DOI 10.32855/dataset.2026.02.049); Apache-2.0, "
                "keep its NOTICE")
    return f"the user's file {mesh.source}: its own licence"
