"""`woody calibrate`: fit the chain physics to the paper's side view, choose the Φ threshold, write the YAML.

The steps, the mesh sets and what is written are :mod:`woody_experiments.calibrate`'s;
this module parses the options and connects to the Dask cluster.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from woody_common.line import MAX_LANES
from woody_experiments import calibrate, cluster
from woody_experiments.mesh_sets import CALIBRATION_MESHES, LOO_MESHES, TEST_MESHES, load_meshes
from woody_tools import arguments


def add_arguments(parser: argparse.ArgumentParser) -> None:
    positives = arguments.POSITIVE_NUMBERS
    parser.add_argument("--meshes", default=None,
                        help=f"calibration meshes (default {CALIBRATION_MESHES}; with --loo: the reference meshes of "
                             f"{LOO_MESHES})")
    parser.add_argument("--fit-meshes", type=int, default=2,
                        help="how many of the calibration meshes the physics fit uses (default 2)")
    parser.add_argument("--test-meshes", default=TEST_MESHES,
                        help="held-out meshes for the threshold report, disjoint from --meshes "
                             f"(default {TEST_MESHES})")
    parser.add_argument("--masses", type=positives, default=[10.0, 20.0, 40.0], help="total masses M (kg) to try")
    parser.add_argument("--dampings", type=positives, default=[0.1, 0.2, 0.4],
                        help="hinge dampers c (N m s/rad) to try")
    parser.add_argument("--frictions", type=positives, default=[0.8], help="drive friction caps mu_static to try")
    parser.add_argument("--skip-physics", action="store_true", help="keep the current physics, choose the threshold")
    parser.add_argument("--skip-threshold", action="store_true", help="fit the physics only")
    parser.add_argument("--out", default="calibration-out", help="folder for calibration.json / calibration.md")
    parser.add_argument("--calibration", default=None,
                        help="calibration file to start from and write (default $WOODY_CALIBRATION, else the installed "
                             "config/calibration.yaml)")
    parser.add_argument("--dry-run", action="store_true", help="print the results, do not write the calibration")
    arguments.add_yaw_sd(parser, "every step, --loo too; recorded in the calibration's provenance")
    arguments.add_top_camera(parser, "the Φ threshold and the line cuts are fitted on what it sees (the physics fit "
                                     "and --loo use the default camera); recorded in the calibration's provenance")
    parser.add_argument("--lanes", type=int, choices=range(1, MAX_LANES + 1), default=MAX_LANES, metavar="N",
                        help=f"lanes of the line the cuts are fitted on (1..{MAX_LANES}, default {MAX_LANES}: every "
                             "place across the belt; fewer for a camera that does not see the widest line)")
    parser.add_argument("--loo", action="store_true",
                        help="leave-one-mesh-out check of the threshold on the reference meshes (k 0/100, 100 and "
                             "130 FPM, with the calibrated physics); writes loo.md / loo.json, writes no calibration")
    cluster.add_arguments(parser, jobs_default=None, probe=False)


def run(args: argparse.Namespace) -> int:
    problem = arguments.out_folder_problem(Path(args.out))
    if problem:
        print(f"woody calibrate: --out {args.out}: {problem}", file=sys.stderr)
        return 2
    problem = arguments.top_camera_problem(args)
    if problem:
        print(f"woody calibrate: {problem}", file=sys.stderr)
        return 2
    try:  # a set without a usable mesh is refused before a cluster starts; the steps find the sets loaded
        for spec in calibrate.mesh_specs(args):
            load_meshes(spec, calibrate.PROGRAM)
    except ValueError as exc:
        print(f"woody calibrate: {exc}", file=sys.stderr)
        return 2
    jobs = args.jobs or cluster.default_jobs()
    try:
        with cluster.connect(args.scheduler, jobs, "woody calibrate") as client:
            return calibrate.calibrate(args, client)
    except cluster.ClusterUnavailable as exc:
        print(f"woody calibrate: {exc}", file=sys.stderr)
        return 2
