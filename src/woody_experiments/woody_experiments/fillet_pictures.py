"""One picture per graded fillet, from a recorded bag: why it was graded so (`woody report BAG`, `woody run`).

Drawn from the grader's annotations (grading/annotations, see woody_vision.annotations), so the picture shows
what a Foxglove user sees: the colour crop at the reference frame and at the measuring-point frame, each with
both outlines, and Φ_t of every scored frame against the reject cut, the verdict's score at the measuring point.
"""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

import numpy as np

from woody_bag.reader import read_bag
from woody_bag.schemas import decode
from woody_bag.summary import bag_topics
from woody_common import topics
from woody_common.stamps import stamp_to_seconds
from woody_vision.annotations import overlays_of
from woody_vision.image_encodings import color_rgb
from woody_vision.overlays import FRAME, MEASURED, REFERENCE, Overlay

COLOUR = "/top_camera/color/image_raw"
MARGIN_PX = 20
FOLDER = "fillets"


def read_overlays(bag: Path) -> dict[int, list[Overlay]]:
    """Every overlay the grader recorded, by track id (the verdict's fillet_id)."""
    by_id: dict[int, list[Overlay]] = defaultdict(list)
    wanted = [t for t in bag_topics(bag) if t.endswith("/" + topics.ANNOTATIONS)]
    for _topic, type_name, data, _log_time in read_bag(bag, topics=wanted):
        for overlay in overlays_of(decode(type_name, data)):
            by_id[overlay.track_id].append(overlay)
    return dict(by_id)


def colour_frames(bag: Path, stamps: set[int]) -> dict[int, np.ndarray]:
    """The top camera's colour images at these stamps (integer nanoseconds)."""
    frames: dict[int, np.ndarray] = {}
    wanted = [t for t in bag_topics(bag) if t.endswith(COLOUR)]
    for _topic, type_name, data, _log_time in read_bag(bag, topics=wanted):
        msg = decode(type_name, data)
        key = _ns(stamp_to_seconds(msg.header.stamp))
        if key in stamps:
            frames[key] = np.array(color_rgb(msg))
    return frames


def write_fillet_pictures(bag: Path, out_dir: Path) -> list[str]:
    """A PNG per fillet with both verdict outlines under ``out_dir/fillets``; the report.md lines linking them."""
    overlays = read_overlays(bag)
    verdicts = {i: {o.kind: o for o in found if o.kind != FRAME} for i, found in overlays.items()}
    verdicts = {i: kinds for i, kinds in verdicts.items() if REFERENCE in kinds}
    if not verdicts:
        return []
    frames = colour_frames(bag, {_ns(o.stamp) for kinds in verdicts.values() for o in kinds.values()})
    (out_dir / FOLDER).mkdir(parents=True, exist_ok=True)
    lines = ["## Each fillet", "", "Colour crops at the reference frame and at the measuring point, the reference "
             "outline in cyan and the measuring-point outline in the verdict's colour; right, Φ_t of each scored "
             "frame against the reject cut (the grader's annotations, grading/annotations).", ""]
    for track_id, kinds in sorted(verdicts.items()):
        name = f"{FOLDER}/fillet-{track_id}.png"
        trace = [(o.stamp, o.phi) for o in overlays[track_id] if o.kind == FRAME and math.isfinite(o.phi)]
        _draw(kinds, frames, sorted(trace), out_dir / name)
        lines += [f"![fillet {track_id}]({name})", ""]
    return lines


def _draw(kinds: dict[str, Overlay], frames: dict[int, np.ndarray], trace: list, path: Path) -> None:
    import matplotlib.pyplot as plt

    reference, measured = kinds[REFERENCE], kinds.get(MEASURED)
    fig, axes = plt.subplots(1, 3, figsize=(10, 3.4), gridspec_kw={"width_ratios": [1, 1, 1.6]})
    outlines = [o for o in (reference, measured) if o is not None]
    box = _box(np.concatenate([o.outline for o in outlines]))
    for ax, at, title in ((axes[0], reference, "reference frame"), (axes[1], measured, "measuring point")):
        image = frames.get(_ns(at.stamp)) if at is not None else None
        if image is not None:
            u0, v0, u1, v1 = _clip(box, image.shape)
            ax.imshow(image[v0:v1, u0:u1], extent=(u0, u1, v1, v0))
        for o, colour in ((reference, "c"), (measured, _colour(reference.label))):
            if o is not None:
                closed = np.vstack([o.outline, o.outline[:1]])
                ax.plot(closed[:, 0], closed[:, 1], color=colour, lw=1.5)
        ax.set_title(f"{title} t={at.stamp:.2f} s" if at is not None else f"{title}: none", fontsize=9)
        ax.set_xlim(box[0], box[2])
        ax.set_ylim(box[3], box[1])
        ax.set_xticks([])
        ax.set_yticks([])
    _plot_trace(axes[2], reference, measured, trace)
    fig.suptitle(f"fillet {reference.track_id}, lane {reference.lane}: {reference.label} (score "
                 f"{_text(reference.score)}, cut {_text(reference.cut)})", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _plot_trace(ax, reference: Overlay, measured: Overlay | None, trace: list) -> None:
    if trace:
        t, phi = np.array(trace).T
        ax.plot(t, phi, "o-", ms=3, color="0.3", label="Φ_t per frame")
    if math.isfinite(reference.cut):
        ax.axhline(reference.cut, color="k", ls="--", lw=0.8, label=f"reject cut {reference.cut:.3g} (below: woody)")
    if measured is not None and math.isfinite(measured.score):
        ax.plot([measured.stamp], [measured.score], "*", ms=12, color=_colour(reference.label),
                label=f"score {measured.score:.3g}")
    ax.set_xlabel("stamp (s)")
    ax.set_ylabel("Φ_t")
    ax.legend(fontsize=7)


def _box(points: np.ndarray) -> tuple[int, int, int, int]:
    (u0, v0), (u1, v1) = points.min(axis=0), points.max(axis=0)
    return int(u0) - MARGIN_PX, int(v0) - MARGIN_PX, int(u1) + MARGIN_PX, int(v1) + MARGIN_PX


def _clip(box: tuple[int, int, int, int], shape: tuple) -> tuple[int, int, int, int]:
    return max(box[0], 0), max(box[1], 0), min(box[2], shape[1]), min(box[3], shape[0])


def _colour(label: str) -> str:
    return {"normal": "g", "woody": "r"}.get(label, "0.5")


def _text(value: float) -> str:
    return f"{value:.3g}" if math.isfinite(value) else "-"


def _ns(seconds: float) -> int:
    return round(seconds * 1e9)
