"""The line's calibrated values as data: a ROS 2 parameters file written by `woody calibrate`.

The file is a ROS 2 parameters file, so the nodes load it with
``--ros-args --params-file FILE`` (`woody run` passes it to ``line_sim`` and
``grader``): ``line_sim`` gets the physics values, ``grader`` the Φ threshold
and the line's cuts. Its provenance (command, date, mesh sets, targets and the
figures reached) sits in the same file under a node name no node uses,
``woody_calibration``, so one file carries values and history.

Which file, decided in one place (:func:`resolve_calibration`): the command's
``--calibration FILE``, else the environment variable ``WOODY_CALIBRATION``,
else the calibration installed with this package (``calibration.yaml``, package
data of ``woody_common.config``, found through :mod:`importlib.resources`;
in the repository it is a link to ``config/calibration.yaml``, the file
`woody calibrate` writes, so an editable install always sees the current
one). :func:`resolved_calibration` reads it; commands resolve it once and pass
the values (or the path, to worker processes) on. A node started from a params
file that gives its calibrated parameters reads no file at all
(:func:`node_defaults`).
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Collection
from dataclasses import asdict, dataclass, field
from importlib import resources
from pathlib import Path

import yaml

ENV_VAR = "WOODY_CALIBRATION"
"""Environment variable naming the calibration file when a command is given no ``--calibration``."""
PACKAGE_DATA = ("woody_common.config", "calibration.yaml")
"""The installed calibration: package data of ``woody_common.config``."""

_SECTIONS = {"line_sim": {"total_mass_kg": "mass", "hinge_damping": "damping", "friction_static": "friction_static",
                          "friction_dynamic": "friction_dynamic"},
             "grader": {"phi_threshold": "threshold", "line_threshold": "line_threshold",
                        "severe_threshold": "severe_threshold",
                        "fitted_range": "fitted_range"}}
"""Per node: dataclass field -> the node's parameter name."""
_PROVENANCE = "woody_calibration"
CUT_FIELDS = ("line_threshold", "severe_threshold")
"""Fields that are cuts (``CUT_LENGTH`` numbers each) rather than single values."""
CUT_LENGTH = 5
"""Numbers per cut (woody_vision.grading.CUT_TERMS; woody_common cannot import woody_vision)."""
RANGE_LENGTH = 5
"""Numbers in the fitted range (woody_vision.grading.RANGE_TERMS)."""
LIST_FIELDS = (*CUT_FIELDS, "fitted_range")


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
    severe_threshold: tuple[float, ...]
    """The grade's moderate/severe cut on ``line_phi``, same form."""
    fitted_range: tuple[float, ...]
    """The measured conditions the cuts were fitted on: [speed min, speed max (m/s), turn max (degrees), body length
    min, max (m)] (woody_vision.grading.FittedRange); the grader leaves a fillet outside them unscored."""
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
        value = self.fitted_range
        if (not isinstance(value, (list, tuple)) or len(value) != RANGE_LENGTH
                or not all(isinstance(v, (int, float)) and math.isfinite(v) and v >= 0 for v in value)):
            raise ValueError(f"calibration: fitted_range must be {RANGE_LENGTH} finite numbers >= 0 "
                             f"(woody_vision.grading.RANGE_TERMS), got {value!r}")
        object.__setattr__(self, "fitted_range", tuple(float(v) for v in value))
        if self.total_mass_kg <= 0.0:
            raise ValueError(f"calibration: total_mass_kg must be > 0, got {self.total_mass_kg}")

    @property
    def speed_range_fpm(self) -> tuple[float, float] | None:
        """(lowest, highest) line speed in FPM the grading cuts were fitted on (provenance ``line_speeds_fpm``,
        written by `woody calibrate`); None when the file does not record them."""
        try:
            speeds = [float(v) for v in str(self.provenance.get("line_speeds_fpm", "")).split(",") if v.strip()]
        except ValueError:
            return None
        return (min(speeds), max(speeds)) if speeds else None

    @property
    def top_camera(self) -> str:
        """The top camera the grading cuts were fitted on (provenance ``top_camera``, :func:`camera_name`, written
        by `woody calibrate --top-camera`); 'default' when the file does not say."""
        return str(self.provenance.get("top_camera", "default"))


def camera_name(top_camera: str) -> str:
    """How a calibration names a top camera: a preset by itself, a camera description file by its name without
    .yaml (wherever it lies)."""
    return Path(top_camera).stem


def _node_key(node: str) -> str:
    return f"/**/{node}"


def installed_calibration() -> Path:
    """The calibration installed with woody_common (package data)."""
    package, name = PACKAGE_DATA
    return Path(str(resources.files(package).joinpath(name)))


def resolve_calibration(explicit: str | Path | None = None) -> Path:
    """The calibration file to use: ``explicit`` (a command's ``--calibration``), else ``$WOODY_CALIBRATION``,
    else :func:`installed_calibration`."""
    if explicit:
        return Path(explicit)
    from_env = os.environ.get(ENV_VAR, "")
    return Path(from_env) if from_env else installed_calibration()


def resolved_calibration(explicit: str | Path | None = None) -> Calibration:
    """Read the calibration :func:`resolve_calibration` picks (the one place a calibration file is read)."""
    return load_calibration(resolve_calibration(explicit))


def node_defaults(node: str, given: Collection[str] | dict = ()) -> dict[str, float | list[float]]:
    """Parameter name -> value of a node's calibrated parameters (``line_sim`` or ``grader``).

    ``given`` maps the parameters the node was started with (its params file and ``-p``
    overrides) to their values: when it holds all of them, those are returned and no file
    is read (a host running only the vision nodes needs no calibration file); otherwise
    the resolved calibration is read once and supplies them.
    """
    names = _SECTIONS[node]
    if isinstance(given, dict) and all(param in given for param in names.values()):
        return {param: _value(given[param], name) for name, param in names.items()}
    calibration = resolved_calibration()
    return {param: _value(getattr(calibration, name), name) for name, param in names.items()}


def load_calibration(path: str | Path) -> Calibration:
    """Read one calibration file; a missing or malformed one raises ValueError naming the file and the problem."""
    path = Path(path)
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
    """Write ``calibration`` as a ROS 2 parameters file (atomically: a reader never sees half a file).

    ``path`` None writes the resolved calibration (:func:`resolve_calibration`); a link (the installed
    calibration in the repository) is followed, so the file it points at is the one replaced."""
    path = resolve_calibration(path).resolve()
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
    """A parameter's value: a list of floats for a cut or the fitted range, else a float."""
    return [float(v) for v in value] if name in LIST_FIELDS else float(value)


def _plain(value):
    """A provenance value as a ROS parameter can hold it: numbers (numpy's too) and strings stay, the rest is text."""
    if isinstance(value, numbers.Integral) and not isinstance(value, bool):
        return int(value)
    if isinstance(value, numbers.Real):
        return float(value)
    return value if isinstance(value, str) else str(value)
