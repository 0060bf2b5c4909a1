"""Parameter declaration and node start-up shared by every woody node.

Each parameter is declared with a description and, for numbers, a range, so
`--ros-args -p name:=value` outside the range is refused by rclpy with the
reason (a whole number given for a decimal parameter is taken as that decimal);
`run_node` turns that refusal (or any ValueError a node raises while
reading its parameters) into one clear line and a non-zero exit instead of a
traceback, and shuts the node down cleanly on Ctrl-C / SIGTERM (summary line, exit 0).
"""

from __future__ import annotations

import array
import math
import re
import signal
import sys
import threading
from collections.abc import Callable

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor


def declare(node, name: str, default, description: str, low: float | None = None, high: float | None = None):
    """Declare a parameter with a descriptor (and an inclusive range for numbers); return its value."""
    descriptor = ParameterDescriptor(description=description, read_only=True)  # every node reads them at start-up
    if low is not None and high is not None:
        if isinstance(default, bool):
            raise TypeError(f"parameter {name}: a bool has no range")
        if isinstance(default, int):
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=1)]
        else:
            descriptor.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high))]
    from rclpy.exceptions import InvalidParameterTypeException

    try:
        value = node.declare_parameter(name, default, descriptor).value
    except InvalidParameterTypeException:
        whole = _whole_number_override(node, name, default)
        if whole is None:
            raise
        value = node.declare_parameter(name, whole, descriptor, ignore_override=True).value
    return _typed(name, default, value)


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


def _typed(name: str, default, value):
    """An override rclpy could not type (``-p name:=[]``) comes back as None: refuse it with the expected form.
    A NaN or infinite decimal is refused too: rclpy's range check lets it through a parameter without a range."""
    if value is None and default is not None:
        example = list(default) if isinstance(default, (list, tuple)) else default
        raise ValueError(f"parameter {name}: needs a value like {example!r}, got an empty or untyped one")
    numbers = list(value) if isinstance(value, (list, tuple, array.array)) else [value]
    if not all(math.isfinite(v) for v in numbers if isinstance(v, float)):
        shown = numbers if isinstance(value, (list, tuple, array.array)) else value
        raise ValueError(f"parameter {name}: must be a finite number, got {shown!r}")
    return value


def calibrated_defaults(node, section: str) -> dict:
    """Defaults of the node's calibrated parameters (``section``: ``line_sim`` or ``grader``): the values its
    params file or ``-p`` give when they give all of them (no file read), else the resolved calibration's
    (woody_common.calibration.node_defaults), read once before the node declares them."""
    from woody_common.calibration import node_defaults

    given = {name: param.value for name, param in node._parameter_overrides.items()}  # noqa: SLF001
    return node_defaults(section, given)


def check_overrides(node) -> None:
    """`ValueError` naming every ``-p name:=value`` the node did not declare (a typo is otherwise silently ignored)."""
    known = set(node._parameters)  # noqa: SLF001 - rclpy keeps declared names and overrides only privately
    unknown = sorted(set(node._parameter_overrides) - known)  # noqa: SLF001
    if unknown:
        raise ValueError(f"unknown parameter{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}; "
                         f"{node.get_name()} knows: {', '.join(sorted(known))}")


def usage(name: str, node=None) -> str:
    """The usage text of a node; with the node built, its parameters with description and range."""
    lines = [f"usage: {name} [--ros-args -p name:=value ... | --params-file FILE]"]
    if node is None:
        return lines[0] + f"\n{name} takes no other arguments; `{name} --help` lists its parameters"
    for param, descriptor in sorted(node._descriptors.items()):  # noqa: SLF001
        ranges = [*descriptor.floating_point_range, *descriptor.integer_range]
        limits = f" [{ranges[0].from_value:g}, {ranges[0].to_value:g}]" if ranges else ""
        lines.append(f"  {param} = {node.get_parameter(param).value!r}{limits}: {descriptor.description}")
    return "\n".join(lines)


def init_checked(name: str, args: list[str] | None, **init_kwargs) -> int | None:
    """rclpy.init with the command line checked: an exit code when the node must not start, else None."""
    import rclpy

    argv = sys.argv if args is None else args
    try:
        extra = non_ros_args(args)
        if extra and extra[0] not in ("-h", "--help"):
            print(f"{name}: unexpected argument {' '.join(extra)}\n{usage(name)}", file=sys.stderr)
            return 2
        rclpy.init(args=argv, **init_kwargs)  # with --help too: it describes the node as configured
    except Exception as exc:  # noqa: BLE001 - rclpy's RCLError / RCLInvalidROSArgsError on a malformed --ros-args
        reason = re.sub(r"^.*?: (?=Couldn't)|\. Error:.*$", "", str(exc).splitlines()[0])
        print(f"{name}: bad --ros-args: {reason}", file=sys.stderr)
        return 2
    return None


def run_node(name: str, factory: Callable[[], object], args: list[str] | None = None,
             help_text: str | None = None) -> int:
    """rclpy.init, build the node, spin until SIGINT/SIGTERM, close it; one-line errors on bad arguments.

    ``--help`` prints the node's parameters; any other non-ROS argument, a malformed or
    unknown ``-p`` override, or a refused value is one line on stderr and exit code 2.
    SIGINT/SIGTERM only set a flag that the spin loop checks, so the node finishes the
    callback it is in, closes (its summary line) and exits 0; rclpy's own handlers would
    invalidate the context under a running callback. A node with ``spin(stop)`` runs its
    own loop until the ``threading.Event`` is set. A node whose construction has side effects
    (the recorder opens its bag) passes ``help_text`` so ``--help`` does not build it; the exit
    code is the node's ``close()`` result when that is non-zero.
    """
    import rclpy
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException, ParameterException
    from rclpy.signals import SignalHandlerOptions

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, stop_handler(stop))
    code = init_checked(name, args, signal_handler_options=SignalHandlerOptions.NO)
    if code is not None:
        return code
    if help_text is not None and non_ros_args(args):
        print(help_text)
        rclpy.try_shutdown()
        return 0
    try:
        node = factory()
        check_overrides(node)
    except (InvalidParameterValueException, InvalidParameterTypeException, ParameterException, ValueError) as exc:
        print(f"{name}: invalid parameter: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    if non_ros_args(args):  # --help: the node was built only to describe itself
        print(usage(name, node))
        _close(node)
        return 0
    try:
        spin = getattr(node, "spin", None)
        code = int(spin(stop) or 0) if spin is not None else _spin_until(node, stop)
    finally:
        closed = _close(node)
    return closed or code


def stop_handler(stop: threading.Event) -> Callable[..., None]:
    """A signal handler that sets ``stop`` once. ``Event.set`` takes a lock, and a second signal arriving while the
    first handler holds it (a parent's death signal and a process-group stop at once) would wait for it forever
    in the same thread: later signals only find the stop under way."""
    first = threading.Lock()

    def handler(*_) -> None:
        if first.acquire(blocking=False):
            stop.set()

    return handler


def _spin_until(node, stop: threading.Event) -> int:
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    while not stop.is_set():
        executor.spin_once(timeout_sec=0.1)
    executor.remove_node(node)
    return 0


def non_ros_args(args: list[str] | None) -> list[str]:
    """The command line without the program name and the ROS arguments (`RCLInvalidROSArgsError` if malformed)."""
    from rclpy.utilities import remove_ros_args

    return remove_ros_args(args=sys.argv if args is None else args)[1:]


def _close(node, ack_budget_s: float = 2.0) -> int:
    """Close the node (its summary line), let subscribers acknowledge what its reliable publishers sent
    (a verdict published just before the stop must still reach the recorder), then destroy it.
    Returns what ``close()`` returned (0 for None)."""
    import time

    import rclpy
    from rclpy.duration import Duration
    from rclpy.qos import ReliabilityPolicy

    deadline = time.monotonic() + ack_budget_s
    for publisher in node.publishers:
        left = deadline - time.monotonic()
        if left > 0 and publisher.qos_profile.reliability == ReliabilityPolicy.RELIABLE:
            publisher.wait_for_all_acked(Duration(seconds=left))
    close = getattr(node, "close", None)
    code = int(close() or 0) if close is not None else 0
    node.destroy_node()
    rclpy.try_shutdown()
    return code
