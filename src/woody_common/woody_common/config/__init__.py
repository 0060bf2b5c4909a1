"""Data installed with woody_common: ``calibration.yaml``, the calibration every node and command falls back to
(woody_common.calibration.installed_calibration)."""
