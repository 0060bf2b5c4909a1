"""reject_gate: an example diverter controller that turns woody verdicts into timed gate commands.

Copy it for your own line. A verdict is stamped with the sim time at which the
fillet's body centre crossed the roller edge; the fillet then reaches its
lane's diverter ``gate_distance_m`` further on at the speed the top camera
measured for it (the verdict's ``speed``; the line speed parameter when the
verdict has none), so the gate opens at
``stamp + distance / speed - open_duration / 2``, and a line whose speed
changes keeps its timing. A verdict that arrives after that moment is late:
it is logged and counted, never acted on. Unscored fillets are diverted by
default (``divert_unscored``): on a crowded or messy line a fillet that could
not be measured cleanly may be woody. The gate keeps no per-fillet state:
every command carries its absolute actuation time. When sim time goes back
(/clock or the verdict stamps; a replay started again) it says so in one log
line, and the verdicts that follow are timed on the new clock.
"""

from __future__ import annotations

import sys

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from woody_common import topics
from woody_common.diagnostics import OK, WARN, DiagnosticsPublisher, Health
from woody_common.line import LANES, MAX_LANES, REFERENCE_SPEED_FPM, SPEED_RANGE_FPM, fpm_to_mps
from woody_common.ros_params import declare, run_node
from woody_common.stamps import seconds_to_stamp, stamp_to_seconds
from woody_msgs.msg import FilletVerdict, GateCommand
from woody_vision.frame_checks import SimTimeWatch, watch_clock
from woody_vision.gate_timing import GATE_DISTANCE_M, GateTiming
from woody_vision.result_qos import RESULTS_DEPTH, results_qos


class RejectGate(Node):
    """Subscribes to /grading/verdicts, publishes /reject_gate/commands."""

    def __init__(self) -> None:
        super().__init__("reject_gate")
        speed_fpm = declare(self, "line_speed_fpm", REFERENCE_SPEED_FPM, "Belt speed in feet per minute (100 "
                            "and 130 are the commercial speeds).", *SPEED_RANGE_FPM)
        lanes = declare(self, "lanes", LANES, "Number of lanes, each with its own diverter.", 1, MAX_LANES)
        distances = list(declare(self, "gate_distance_m", [GATE_DISTANCE_M], "Distance from the roller edge to each "
                                 "lane's diverter (m): one value for all lanes or one per lane."))
        open_duration = declare(self, "open_duration_s", 0.3, "How long a diverter stays open (s).", 0.01, 5.0)
        self.divert_unscored = declare(self, "divert_unscored", True, "Also divert fillets that could not be "
                                       "scored (fail safe: one that could not be measured may be woody).")
        if len(distances) not in (1, lanes):
            raise ValueError(f"gate_distance_m needs 1 or {lanes} values, got {len(distances)}")
        self.timing = GateTiming(line_speed_mps=fpm_to_mps(speed_fpm),
                                 gate_distances_m=distances if len(distances) == lanes else distances * lanes,
                                 open_duration_s=open_duration)
        self.diverted = 0
        self.late = 0
        self.passed = 0
        self.publisher = self.create_publisher(GateCommand, topics.GATE_COMMANDS, results_qos())
        verdicts = QoSProfile(depth=RESULTS_DEPTH, reliability=ReliabilityPolicy.RELIABLE)  # volatile: new ones only
        self.create_subscription(FilletVerdict, topics.VERDICTS, self.on_verdict, verdicts)
        self.sim_time = SimTimeWatch()
        self.clock_jumps = watch_clock(self, self.sim_time, self.time_went_back)
        self.diagnostics = DiagnosticsPublisher(self, self.health)

    def health(self) -> Health:
        """Late commands are fillets the gate could not divert in time: a warning."""
        counts = {"diverted": self.diverted, "late": self.late, "passed": self.passed}
        line = f"{self.diverted} diverted, {self.late} late, {self.passed} passed"
        return Health(WARN if self.late else OK, line, counts)

    def time_went_back(self, why: str) -> None:
        self.get_logger().warning(f"sim time went back ({why}): the verdicts that follow are timed on the new "
                                  f"clock ({self.diverted} diverted, {self.late} late, {self.passed} passed so far)")

    def close(self) -> None:
        print(f"[reject_gate] diverted {self.diverted}, late {self.late}, passed {self.passed}", flush=True)

    def on_verdict(self, verdict: FilletVerdict) -> None:
        crossing = stamp_to_seconds(verdict.header.stamp)
        if self.sim_time.went_back("verdicts", crossing):
            self.time_went_back(f"{topics.VERDICTS} stamp went back to {crossing:.2f} s")
        woody = verdict.classification == FilletVerdict.CLASS_WOODY
        unscored = verdict.classification == FilletVerdict.CLASS_UNSCORED
        if not (woody or (unscored and self.divert_unscored)):
            self.passed += 1
            return
        now = self.get_clock().now().nanoseconds * 1e-9
        try:
            actuation = self.timing.actuation_time(verdict.lane, crossing, verdict.speed)
        except ValueError as exc:
            self.get_logger().error(f"verdict for fillet {verdict.fillet_id}: {exc}; not acted on")
            return
        if actuation < now:
            self.late += 1
            self.get_logger().warning(
                f"late verdict for fillet {verdict.fillet_id} in lane {verdict.lane}: gate time {actuation:.3f} s "
                f"already passed at {now:.3f} s ({self.late} late so far); not diverted")
            return
        command = GateCommand(lane=verdict.lane, fillet_id=verdict.fillet_id, open_duration=self.timing.open_duration_s,
                              phi=verdict.phi, actuation_time=seconds_to_stamp(actuation))
        command.header.stamp = self.get_clock().now().to_msg()
        command.header.frame_id = verdict.header.frame_id
        self.publisher.publish(command)
        self.diverted += 1
        why = verdict.unscored_reason if unscored else f"score {verdict.score:.2f} < {verdict.threshold:.2f}"
        self.get_logger().info(f"divert fillet {verdict.fillet_id} lane {verdict.lane} at {actuation:.3f} s, "
                               f"{actuation - now:.3f} s ahead ({why}); {self.diverted} diverted")


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node("reject_gate", RejectGate, args))


if __name__ == "__main__":
    main()
