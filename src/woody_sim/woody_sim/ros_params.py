"""Parameter declaration and node start-up shared by every woody node.

Each parameter is declared with a description and, for numbers, a range, so
`--ros-args -p name:=value` outside the range is refused by rclpy with the
reason (a whole number given for a decimal parameter is taken as that decimal);
`run_node` turns that refusal (or any ValueError a node raises while
reading its parameters) into one clear line and a non-zero exit instead of a
traceback, and shuts the node down cleanly on Ctrl-C / SIGTERM.
"""

from __future__ import annotations

import sys
from typing import Callable

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor


def declare(node, name: str, default, description: str, low: float | None = None, high: float | None = None):
    """Declare a parameter with a descriptor (and an inclusive range for numbers); return its value."""
    descriptor = ParameterDescriptor(description=description)
    if low is not None and high is not None:
        if isinstance(default, bool):
            raise TypeError(f"parameter {name}: a bool has no range")
        if isinstance(default, int):
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=1)]
        else:
            descriptor.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high))]
    from rclpy.exceptions import InvalidParameterTypeException

    try:
        return node.declare_parameter(name, default, descriptor).value
    except InvalidParameterTypeException:
        whole = _whole_number_override(node, name, default)
        if whole is None:
            raise
        return node.declare_parameter(name, whole, descriptor, ignore_override=True).value


def _whole_number_override(node, name: str, default):
    """A whole-number override of a decimal parameter (``-p speed:=130``) as a float (or float list), else None."""
    if not (isinstance(default, float) or (isinstance(default, list) and all(isinstance(v, float) for v in default))):
        return None
    probe = node.declare_parameter(name, default, ParameterDescriptor(dynamic_typing=True)).value
    node.undeclare_parameter(name)
    if isinstance(default, float) and isinstance(probe, int) and not isinstance(probe, bool):
        return float(probe)
    if isinstance(default, list) and isinstance(probe, (list, tuple)) and all(
            isinstance(v, int) and not isinstance(v, bool) for v in probe):
        return [float(v) for v in probe]
    return None


def run_node(name: str, factory: Callable[[], object], args: list[str] | None = None) -> int:
    """rclpy.init, build the node, spin until Ctrl-C/SIGTERM, shut down; one-line errors on bad parameters."""
    import rclpy
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException, ParameterException
    from rclpy.executors import ExternalShutdownException

    rclpy.init(args=args)
    try:
        node = factory()
    except (InvalidParameterValueException, InvalidParameterTypeException, ParameterException, ValueError) as exc:
        print(f"{name}: invalid parameter: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    code = 0
    try:
        spin = getattr(node, "spin", None)
        if spin is not None:
            code = int(spin() or 0)
        else:
            rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        close = getattr(node, "close", None)
        if close is not None:
            close()
        node.destroy_node()
        rclpy.try_shutdown()
    return code
