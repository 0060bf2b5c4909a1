"""`woody meshes stats`: the table, the JSON file, the segmenter's footprint (bad meshes and specs:
tests/bad_input/test_meshes.py)."""

from __future__ import annotations

import json

from woody_sim.mesh_stats import DESCRIPTOR_NAMES
from woody_tools.cli import main


def test_stats_prints_each_set_and_writes_json(tmp_path, capsys) -> None:
    out = tmp_path / "stats.json"
    assert main(["meshes", "stats", "generated:2:5", "generated:1:6", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "set generated:2:5: 2 meshes" in printed and "generated-50001" in printed and "  mean" in printed
    report = json.loads(out.read_text())
    assert [s["spec"] for s in report["sets"]] == ["generated:2:5", "generated:1:6"]
    first = report["sets"][0]
    assert [m["name"] for m in first["meshes"]] == ["generated-50000", "generated-50001"]
    assert set(first["summary"]) == set(DESCRIPTOR_NAMES)
    widths = [first["meshes"][0][f"width_{p}"] for p in (10, 25, 50, 75, 90)]
    assert all(0.0 < w <= 1.0 for w in widths)


def test_height_threshold_gives_the_segmenters_smaller_footprint(tmp_path, capsys) -> None:
    silhouette, segmenter = tmp_path / "a.json", tmp_path / "b.json"
    assert main(["meshes", "stats", "generated:1:5", "--json", str(silhouette)]) == 0
    assert main(["meshes", "stats", "generated:1:5", "--json", str(segmenter), "--height-threshold", "0.005"]) == 0
    areas = [json.loads(p.read_text())["sets"][0]["meshes"][0]["area_m2"] for p in (silhouette, segmenter)]
    assert areas[1] < 0.95 * areas[0]
    assert main(["meshes", "stats", "generated:1", "--height-threshold", "-1"]) == 2
    assert "--height-threshold" in capsys.readouterr().err
