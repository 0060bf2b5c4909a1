"""Grade a `woody evaluate` folder's recorded runs again through the vision's modules, offline (docs/results.md).

Each run's line.mcap holds the top camera's depth frames and the line's
ground truth. They go frame by frame through what the segmenter and grader
nodes run (segment_depth, CentroidTracker, belt_outline, FilletGrader) with
the code as it is now, and the verdicts are matched to the fillets as
`woody run` matches them. The physics is not run again, so a change to the
vision is measured on the very frames the live grid saw, in about 4 s a run
instead of 25; the live grid stays the figure the docs report. For the
straight-down default camera and the grader's default roller edge, which
`woody evaluate` uses.

    .venv/bin/python tools/replay_evaluation.py evaluate-out [--no-split-by-tracks]
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from woody_bag.reader import read_bag
from woody_bag.schemas import decode
from woody_common import topics
from woody_common.line import (
    LANE_PITCH_M,
    LANES,
    TOP_CAMERA_HEIGHT_M,
    TOP_EDGE_OFFSET_M,
)
from woody_common.stamps import stamp_to_seconds
from woody_experiments.live_evaluation import (
    LIVE_CONDITIONS,
    RUNS_DIR,
    Cell,
    failures_by_reason,
    summary_lines,
    tally,
    woody_not_diverted,
)
from woody_experiments.messages import spawn_from_msg, verdict_from_msg
from woody_experiments.run_report import join
from woody_vision.camera_model import LaneLayout, belt_outline, edge_row
from woody_vision.grader_core import FilletGrader, TrackObservation
from woody_vision.image_encodings import depth_metres
from woody_vision.segmentation import BackgroundModel, SegmentationParams, segment_depth
from woody_vision.tracking import CentroidTracker
from woody_vision.verdict_message import verdict_message


def run_setup(run: Path) -> tuple[float, float, LaneLayout]:
    """The run's roller edge row, camera height and lane layout: its camera_info's K with the line's defaults,
    and the lanes, lane pitch and camera height its segmenter ran with when the run kept its logs (as every
    `woody evaluate` run does)."""
    info = next(iter(read_bag(run / "line.mcap", ["/" + topics.TOP_DEPTH_INFO])))
    k = tuple(decode(info.type_name, info.data).k)
    params = run / "logs" / "segmenter.params.yaml"
    text = params.read_text() if params.exists() else ""
    height = _parameter(text, "camera_height_m", TOP_CAMERA_HEIGHT_M)
    lanes, pitch = int(_parameter(text, "lanes", LANES)), _parameter(text, "lane_pitch_m", LANE_PITCH_M)
    layout = LaneLayout(k, height, lanes, pitch)
    return edge_row(k, height, TOP_EDGE_OFFSET_M), height, layout


def _parameter(params_yaml: str, name: str, default: float) -> float:
    match = re.search(rf"\b{name}: ([0-9.]+)", params_yaml)
    return float(match.group(1)) if match else default


def replay_run(run: Path, split_by_tracks: bool) -> list[dict]:
    """The run's rows (run_report.join) with its depth frames graded again."""
    edge, height, layout = run_setup(run)
    params = SegmentationParams(split_by_tracks=split_by_tracks).for_camera(layout.k, height)
    background, tracker = BackgroundModel(5), CentroidTracker(lane_layout=layout)
    grader = FilletGrader(edge, pixels_per_metre=layout.k[4] / height)
    verdicts = []
    for message in read_bag(run / "line.mcap", ["/" + topics.TOP_DEPTH_IMAGE]):
        image = decode(message.type_name, message.data)
        depth, stamp = depth_metres(image), stamp_to_seconds(image.header.stamp)
        if not background.ready:
            background.add(depth)
            continue
        blobs = segment_depth(depth, background.depth, params, priors=tracker.predicted_outlines(stamp))
        update = tracker.update(blobs, stamp)
        tracks = [TrackObservation(t.track_id, max(t.lane, 0), belt_outline(t.blob.contour, depth, layout.k, height),
                                   t.unseen, t.blob.contour) for t in update.active]
        graded = grader.on_tracks(stamp, tracks, [t.track_id for t in update.ended])
        verdicts += [verdict_from_msg(verdict_message(g, grader.rules, "", stamp)) for g in graded]
    truth = read_bag(run / "line.mcap", ["/" + topics.GROUND_TRUTH])
    spawns = [spawn_from_msg(decode(m.type_name, m.data)) for m in truth]
    return [{**row, "run": run.name} for row in join(spawns, verdicts)]


def _cell(name: str) -> Cell | None:
    """The grid cell a run folder's name gives (None for a folder of another name)."""
    try:
        return Cell.from_name(name)
    except ValueError:
        return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a woody evaluate --out folder")
    parser.add_argument("--no-split-by-tracks", dest="split_by_tracks", action="store_false",
                        help="the segmenter's split_by_tracks:=false")
    args = parser.parse_args()
    rows, cells = [], []
    runs = sorted((args.folder / RUNS_DIR).iterdir())
    for run in runs:
        cell = _cell(run.name)
        rows += [{**(cell.columns if cell else {}), **row} for row in replay_run(run, args.split_by_tracks)]
        cells += [cell] if cell else []
        print(f"  {run.name}", flush=True)
    if len(cells) == len(runs):  # every run a cell of the grid: its table, as woody evaluate prints it
        order = sorted(cells, key=lambda c: (LIVE_CONDITIONS.index(c.condition), c.lanes, c.speed_fpm))
        print("\n".join(summary_lines(rows, order)))
    t = tally(rows)
    print(f"{t.runs} runs, {t.fillets} fillets: right {t.right}, unscored {t.unscored}, missing {t.missing}, "
          f"extra {t.extra}, woody not diverted {t.woody_not_diverted} of {t.woody}")
    for reason, failed in failures_by_reason(rows):
        print(f"  {len(failed):4d}  {reason}")
    for row in woody_not_diverted(rows):
        print(f"  woody not diverted: {row['run']} fillet {row['fillet_id']} lane {row['lane']} {row['mesh']} "
              f"score {row['score']} cut {row['threshold']}")


if __name__ == "__main__":
    main()
