"""The paper's figures and the reproduction targets, as data (``/work/shared/reference/targets.md``).

The sweep report prints them beside the project's figures, the physics fit
minimises the distance to the side-view table and the calibration reports
against the same bands: one place to read or change what "reproduced" means.
"""

PAPER_SIDE = {  # FPM -> k -> (NMDM, MDM px, BE); simulated, M = 100 (Table sv_results)
    100.0: {0.0: (0.520, 45.8, 37.6), 10.0: (0.601, 52.6, 25.1), 100.0: (0.783, 68.3, 19.3),
            200.0: (0.824, 71.8, 10.0), 400.0: (0.848, 74.0, 10.5)},
    130.0: {0.0: (0.675, 59.0, 27.8), 10.0: (0.716, 62.6, 17.4), 100.0: (0.820, 71.5, 12.9),
            200.0: (0.843, 73.6, 8.8), 400.0: (0.863, 75.3, 7.1)},
}
PAPER_NMDM = {(speed, k): row[0] for speed, table in PAPER_SIDE.items() for k, row in table.items()}
"""(FPM, k) -> NMDM of the paper's simulated side view."""
PAPER_BIOLOGICAL = [  # Yoon et al., averaged over 10-100 FPM: condition, NMDM, MDM, BE
    ("normal", "0.41 ± 0.10", "41 ± 11", "35 ± 20"),
    ("moderate WB", "0.63 ± 0.05", "63 ± 5", "9 ± 5"),
    ("severe WB", "0.66 ± 0.08", "67 ± 7", "7 ± 7"),
]
PAPER_TOP = {  # FPM -> k -> (Φ mean, Φ sd, Hu term, solidity term); 1,000 meshes, M = 100 (Table tdv_results)
    100.0: {0.0: (19.12, 5.67, 0.178, 0.014), 20.0: (11.16, 4.42, 0.104, 0.008), 40.0: (8.79, 3.65, 0.082, 0.007),
            60.0: (7.09, 3.10, 0.066, 0.006), 80.0: (6.28, 2.83, 0.058, 0.005), 100.0: (5.40, 2.54, 0.050, 0.005)},
    130.0: {0.0: (14.91, 5.44, 0.139, 0.011), 20.0: (7.27, 3.56, 0.067, 0.006), 40.0: (5.88, 3.22, 0.054, 0.005),
            60.0: (4.87, 2.82, 0.045, 0.005), 80.0: (4.25, 2.28, 0.039, 0.004), 100.0: (4.01, 3.03, 0.036, 0.004)},
}
PAPER_LANES = {  # lane -> (normal Φ mean, sd, severe Φ mean, sd, ΔΦ) at 100 FPM (Table lane_analysis)
    0: (19.06, 5.53, 5.28, 2.56, 13.78),
    1: (19.34, 5.81, 5.14, 2.49, 14.20),
    2: (18.97, 5.66, 5.78, 2.54, 13.20),
}
PAPER_DELTA_NMDM = 0.263
PHYSICAL_DELTA_NMDM = 0.25

# ------------------------------------------------------------------ targets of the reproduction
DELTA_NMDM_RANGE = (0.20, 0.32)
"""ΔNMDM(k=100 − k=0) at 100 FPM: the paper 0.263, the physical study ≈ 0.25."""
NMDM_NORMAL_RANGE = (0.42, 0.62)
SPEED_GAIN_MIN = 0.05
"""NMDM(k=0) at 130 FPM must exceed its 100 FPM value by at least this (paper: +0.155)."""
PHI_SPEED_DROP_MIN = 0.10
"""Φ(k=0) at 130 FPM at least 10 % below its 100 FPM value (paper −22 %)."""
PHI_SD_FACTOR = 1.5
"""The Φ sd per class within this factor of the paper's (100 FPM)."""
PHI_RATIO_MIN = 3.0
ACCURACY_MIN = 0.97
