"""`tools/replay_evaluation.py` grades a recorded run again: on the sample bag it gives the verdicts the live grader
published, fillet for fillet, and prints the tally of a `woody evaluate` folder."""

from __future__ import annotations

import math
import subprocess
import sys

from conftest import REPO

from woody_experiments.run_report import read_csv

SAMPLE = REPO / "bags" / "sample"


def test_the_sample_bag_replayed_gives_the_verdicts_its_grader_published(tmp_path):
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "sample").symlink_to(SAMPLE, target_is_directory=True)
    result = subprocess.run([sys.executable, str(REPO / "tools" / "replay_evaluation.py"), str(tmp_path)],
                            capture_output=True, text=True, timeout=300, cwd=REPO)
    assert result.returncode == 0, result.stderr[-2000:]
    live = read_csv(SAMPLE / "verdicts.csv")
    right = sum((row["verdict"] in ("woody", "unscored")) == (row["truth"] == "woody") for row in live)
    assert f"1 runs, {len(live)} fillets: right {right}, unscored 0, missing 0, extra 0" in result.stdout


def test_each_replayed_fillet_has_its_live_verdict_and_score():
    sys.path.insert(0, str(REPO / "tools"))
    try:
        from replay_evaluation import replay_run
    finally:
        sys.path.remove(str(REPO / "tools"))
    replayed = {str(row["sim_id"]): row for row in replay_run(SAMPLE, split_by_tracks=True)}
    for row in read_csv(SAMPLE / "verdicts.csv"):
        again = replayed[row["sim_id"]]
        assert again["verdict"] == row["verdict"]
        # within 2 %: the scores the live grader published for this bag differ from the replay's by 0.1 % or less
        assert math.isclose(again["line_phi"], row["line_phi"], rel_tol=0.02)
