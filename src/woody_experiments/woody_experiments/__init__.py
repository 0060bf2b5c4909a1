"""Headless experiments: the line's science run without ROS, on one machine or a Dask cluster.

`experiment` (one run: a mesh in every lane at one k and speed), `sweep` (the
paper's grid and its ``runs.csv``), `mesh_sets`, `cluster` (Dask execution),
`calibrate` and `physics_fit`, `statistics` (the one statistics module),
`evaluation` (one vote per run, leave-one-out), `traces`, `soak`,
`paper_targets` (the paper's figures as data), the reports (`sweep_report`,
`run_report`) and `messages` (the line's messages as the run report's records).
"""
