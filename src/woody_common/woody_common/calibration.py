"""The line's calibrated values as data: `config/calibration.yaml`, written by `woody calibrate`.

The file is a ROS 2 parameters file, so the nodes load it with
``--ros-args --params-file config/calibration.yaml`` (`woody run` passes it to
every node): ``line_sim`` gets the physics values, ``grader`` the Φ threshold.
Its provenance (command, date, mesh sets, targets and the figures reached)
sits in the same file under a node name no node uses, ``woody_calibration``,
so one file carries values and history. The sweeps and calibration read it
with :func:`load_calibration`; nothing rewrites Python source.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass, field
from pathlib import Path

import yaml

DEFAULT_PATH = Path(__file__).resolve().parents[3] / "config" / "calibration.yaml"
"""The repository's calibration file (the packages are installed editable from the repository)."""

_SECTIONS = {"line_sim": {"total_mass_kg": "mass", "hinge_damping": "damping", "friction_static": "friction_static",
                          "friction_dynamic": "friction_dynamic"},
             "grader": {"phi_threshold": "threshold", "line_threshold": "line_threshold",
                        "moderate_threshold": "moderate_threshold", "severe_threshold": "severe_threshold"}}
"""Per node: dataclass field -> the node's parameter name."""
_PROVENANCE = "woody_calibration"
CUT_FIELDS = ("line_threshold", "moderate_threshold", "severe_threshold")
CUT_LENGTH = 5
"""Numbers per cut (woody_vision.grading.CUT_TERMS; woody_common cannot import woody_vision)."""
"""Fields that are cuts (three numbers each) rather than single values."""


@dataclass(frozen=True)
class Calibration:
    """What `woody calibrate` fits and every simulation and grader uses."""

    total_mass_kg: float
    """Total chain mass M (kg), the paper's tuning mass."""
    hinge_damping: float
    """Hinge damper c (N m s / rad)."""
    friction_static: float
    """Coulomb cap of the belt drive while a segment holds the belt speed."""
    friction_dynamic: float
    """Coulomb cap once it slips."""
    phi_threshold: float
    """The paper's rule: Φ strictly below this is woody."""
    line_threshold: tuple[float, ...]
    """The line's reject cut on ``line_phi``: [base, speed_slope, blunt_offset, turn_slope, length_slope]
    (woody_vision.grading.Cut)."""
    moderate_threshold: tuple[float, ...]
    """The grade's normal/moderate cut on ``line_phi``, same form."""
    severe_threshold: tuple[float, ...]
    """The grade's moderate/severe cut on ``line_phi``, same form."""
    provenance: dict = field(default_factory=dict, compare=False)
    """command, date, mesh sets, targets and achieved figures (free-form, flat str/float values)."""

    def __post_init__(self) -> None:
        for name in ("total_mass_kg", "hinge_damping", "friction_static", "friction_dynamic", "phi_threshold"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0.0:
                raise ValueError(f"calibration: {name} must be a finite number >= 0, got {value!r}")
        for name in CUT_FIELDS:
            value = getattr(self, name)
            if (not isinstance(value, (list, tuple)) or len(value) != CUT_LENGTH
                    or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in value) or value[0] <= 0):
                raise ValueError(f"calibration: {name} must be {CUT_LENGTH} finite numbers, the first > 0 "
                                 f"(woody_vision.grading.CUT_TERMS), got {value!r}")
            object.__setattr__(self, name, tuple(float(v) for v in value))
        if self.total_mass_kg <= 0.0:
            raise ValueError(f"calibration: total_mass_kg must be > 0, got {self.total_mass_kg}")


def _node_key(node: str) -> str:
    return f"/**/{node}"


def load_calibration(path: str | Path | None = None) -> Calibration:
    """Read a calibration file; a missing or malformed one raises ValueError naming the file and the problem."""
    path = Path(path) if path is not None else DEFAULT_PATH
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ValueError(f"{path}: cannot read the calibration: {exc}") from None
    values: dict = {}
    try:
        for node, names in _SECTIONS.items():
            params = data[_node_key(node)]["ros__parameters"]
            values.update({name: _value(params[param], name) for name, param in names.items()})
        provenance = dict(data.get(_node_key(_PROVENANCE), {}).get("ros__parameters", {}))
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ValueError(f"{path}: not a woody calibration file ({exc!r} missing or malformed)") from None
    return Calibration(**values, provenance=provenance)


def write_calibration(calibration: Calibration, path: str | Path | None = None, header: str = "") -> Path:
    """Write ``calibration`` as a ROS 2 parameters file (atomically: a reader never sees half a file)."""
    path = Path(path) if path is not None else DEFAULT_PATH
    values = {name: _value(value, name) for name, value in asdict(calibration).items() if name != "provenance"}
    data = {_node_key(node): {"ros__parameters": {param: values[name] for name, param in names.items()}}
            for node, names in _SECTIONS.items()}
    data[_node_key(_PROVENANCE)] = {"ros__parameters": {k: _plain(v) for k, v in calibration.provenance.items()}}
    text = "".join(f"# {line}\n" for line in header.splitlines()) + yaml.safe_dump(data, sort_keys=False)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(text)
    tmp.replace(path)
    return path


def _value(value, name: str):
    """A parameter's value: a list of floats for a cut, else a float."""
    return [float(v) for v in value] if name in CUT_FIELDS else float(value)


def _plain(value):
    """A provenance value as a ROS parameter can hold it: numbers (numpy's too) and strings stay, the rest is text."""
    if isinstance(value, numbers.Integral) and not isinstance(value, bool):
        return int(value)
    if isinstance(value, numbers.Real):
        return float(value)
    return value if isinstance(value, str) else str(value)
