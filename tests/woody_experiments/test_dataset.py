"""`woody dataset`: COCO files pycocotools loads, masks equal to the renderer's own coverage, whole window
sequences labelled like verdicts.csv, splits by mesh, identical bytes on a rerun, resume."""

from __future__ import annotations

import csv
import hashlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pycocotools import mask as coco_mask
from pycocotools.coco import COCO

from woody_experiments import dataset
from woody_experiments.experiment import RunSpec
from woody_experiments.line_grade import true_grade
from woody_experiments.mesh_sets import load_meshes
from woody_experiments.run_report import truth_of
from woody_sim.rendering import LineRenderer

ARGS = ["dataset", "--meshes", "generated:3:11", "--k", "0,100", "--speeds", "130", "--lanes", "2", "--jobs", "1"]


def _woody(*args: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-c", "import sys; from woody_tools.cli import main; sys.exit(main(sys.argv[1:]))", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)


def _checksums(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("dataset") / "set"
    result = _woody(*ARGS, "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "frames/min" in result.stderr and "reference workload" in result.stderr
    return out


@pytest.mark.slow
def test_every_split_loads_in_pycocotools_with_one_annotation_per_fillet_in_view(made):
    splits = json.loads((made / "splits.json").read_text())["splits"]
    images = 0
    for split, meshes in splits.items():
        coco = COCO(str(made / "annotations" / f"top_{split}.json"))
        assert {c["name"] for c in coco.loadCats(coco.getCatIds())} == {"normal", "moderate", "severe"}
        for image in coco.loadImgs(coco.getImgIds()):
            assert (made / image["file_name"]).is_file() and (made / image["depth_file"]).is_file()
            annotations = coco.loadAnns(coco.getAnnIds(imgIds=image["id"]))
            lanes = [a["attributes"]["lane"] for a in annotations]
            assert len(lanes) == len(set(lanes))
            for a in annotations:
                assert a["attributes"]["mesh"] in meshes
                assert coco.annToMask(a).sum() == a["area"] > 0
            images += 1
    assert images > 0


@pytest.mark.slow
def test_the_splits_are_by_mesh(made):
    splits = json.loads((made / "splits.json").read_text())["splits"]
    named = [m for meshes in splits.values() for m in meshes]
    assert len(named) == len(set(named)) == 3
    assert all(splits[s] for s in dataset.SPLITS)


@pytest.mark.slow
def test_sequences_hold_every_window_frame_and_the_labels_of_verdicts_csv(made):
    with (made / "fillets.csv").open(newline="") as fh:
        rows = {(r["run"], int(r["lane"])): r for r in csv.DictReader(fh)}
    assert len(rows) == 3 * 2 * 2
    for run, record in dataset.read_records(made).items():
        for fillet in record["fillets"]:
            sequence = json.loads((made / "sequences" / run / f"lane{fillet['lane']}" / "sequence.json").read_text())
            stamps = {f["stamp"] for f in sequence["frames"]}
            window = {round(s, 6) for s in fillet["window_stamps"]}
            assert window and window <= stamps
            assert sum(f["in_window"] for f in sequence["frames"]) == len(window)
            labels, row = sequence["labels"], rows[(run, fillet["lane"])]
            assert labels["truth"] == row["truth"] == truth_of(labels["k"], dataset.WOODY_K)
            assert labels["true_grade"] == row["true_grade"] == true_grade(labels["k"])
            assert (labels["mesh"], labels["lane"], labels["speed_fpm"]) == (row["mesh"], int(row["lane"]),
                                                                            float(row["speed_fpm"]))
            for f in sequence["frames"]:
                assert (made / "sequences" / run / f"lane{fillet['lane']}" / "mask" / f["file"]).is_file()


@pytest.mark.slow
def test_a_rerun_with_the_same_seed_writes_identical_files_and_a_resume_renders_nothing(made, tmp_path):
    again = tmp_path / "again"
    result = _woody(*ARGS, "--out", str(again))
    assert result.returncode == 0, result.stderr
    assert _checksums(again) == _checksums(made)
    resumed = _woody(*ARGS, "--out", str(again))
    assert resumed.returncode == 0 and "0 to go" in resumed.stderr
    assert _checksums(again) == _checksums(made)
    other = _woody(*ARGS, "--out", str(again), "--seed", "3")
    assert other.returncode == 2
    assert other.stderr.strip().splitlines()[-1].startswith("woody dataset: ") and "--seed" in other.stderr


def test_every_instance_mask_is_the_renderers_own_coverage_of_its_fillet(tmp_path, monkeypatch):
    """Each fillet rendered alone over the empty scene covers the pixels its annotation names (IoU >= 0.99)."""
    coverage: list[dict[int, np.ndarray]] = []
    render_top = LineRenderer.render_top

    def covering(self, poses, instances=None):
        if instances is not None:
            background = render_top(self, {})[1]
            coverage.append({fid: render_top(self, {fid: pose})[1] < background for fid, pose in poses.items()})
        return render_top(self, poses, instances)

    monkeypatch.setattr(LineRenderer, "render_top", covering)
    name = "generated-0005"
    mesh = load_meshes("generated:6", "test")[name]
    spec = RunSpec(name, 100.0, 130.0, lanes=3, side=False, condition="messy")
    [record] = dataset.render_run(spec, mesh, dataset.RunOptions(out=str(tmp_path)))
    assert len(record["frames"]) == len(coverage) > 20
    copies = 0
    for frame, covered in zip(record["frames"], coverage):
        assert len(frame["fillets"]) == sum(1 for c in covered.values() if c.any())
        for instance in frame["fillets"]:
            mask = coco_mask.decode(instance["segmentation"]).astype(bool)
            own = [c for c in covered.values() if (c & mask).any()]
            assert len(own) == 1
            iou = (own[0] & mask).sum() / (own[0] | mask).sum()
            assert iou >= 0.99
            copies += 1
    assert copies > 60


def test_splits_never_share_a_mesh_and_follow_the_seed():
    names = [f"m{i}" for i in range(10)]
    splits = dataset.split_meshes(names, 0)
    assert sorted(splits) == names
    counts = {s: sum(1 for v in splits.values() if v == s) for s in dataset.SPLITS}
    assert counts == {"train": 6, "val": 2, "test": 2}
    assert dataset.split_meshes(names, 0) == splits != dataset.split_meshes(names, 1)
    assert set(dataset.split_meshes(["a", "b"], 0).values()) == {"train", "test"}
    assert set(dataset.split_meshes(["a"], 0).values()) == {"train"}


def test_depth_png_is_millimetres_with_zero_for_no_return():
    depth = np.array([[0.7504, np.nan], [np.inf, 70.0]], np.float32)
    assert dataset.depth_png(depth).tolist() == [[750, 0], [0, 65535]]
    assert dataset.depth_png(depth).dtype == np.uint16


def test_rle_round_trips():
    mask = np.zeros((5, 7), bool)
    mask[1:3, 2:6] = True
    rle = dataset.encode_mask(mask)
    assert isinstance(rle["counts"], str) and rle["size"] == [5, 7]
    assert (coco_mask.decode({"size": rle["size"], "counts": rle["counts"].encode()}) == mask).all()
