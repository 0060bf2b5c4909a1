"""rosbag2's ``offered_qos_profiles`` channel metadata: written from rclpy QoS profiles, parsed back to dicts."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

_INFINITE = (9223372036, 854775807)


def _enum_name(value: Any) -> str:
    name = getattr(value, "name", None)
    if name is None:
        return str(value).lower()
    return name.lower()


def _duration(value: Any) -> tuple[int, int]:
    ns = getattr(value, "nanoseconds", None)
    if ns is None or ns <= 0 or ns >= 2**63 - 1:
        return _INFINITE
    return ns // 1_000_000_000, ns % 1_000_000_000


def qos_profiles_yaml(profiles: Iterable[Any]) -> str:
    """rosbag2 (Jazzy) ``offered_qos_profiles`` YAML for rclpy `QoSProfile` objects."""
    out = []
    for qos in profiles:
        lines = [
            f"- history: {_enum_name(qos.history)}",
            f"  depth: {int(qos.depth)}",
            f"  reliability: {_enum_name(qos.reliability)}",
            f"  durability: {_enum_name(qos.durability)}",
        ]
        for key in ("deadline", "lifespan"):
            sec, nsec = _duration(getattr(qos, key, None))
            lines += [f"  {key}:", f"    sec: {sec}", f"    nsec: {nsec}"]
        lines.append(f"  liveliness: {_enum_name(qos.liveliness)}")
        sec, nsec = _duration(getattr(qos, "liveliness_lease_duration", None))
        lines += ["  liveliness_lease_duration:", f"    sec: {sec}", f"    nsec: {nsec}"]
        lines.append(f"  avoid_ros_namespace_conventions: {'true' if qos.avoid_ros_namespace_conventions else 'false'}")
        out.append("\n".join(lines))
    return "\n".join(out)


def subscription_qos(publishers: Iterable[Any], depth: int) -> Any:
    """rosbag2's adaptive rule for subscribing to what ``publishers`` (rclpy TopicEndpointInfo) offer: reliable
    unless one is best-effort, transient-local (latched) when every one is, keep-last ``depth``."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    offered = [p.qos_profile for p in publishers]
    reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
    latched = all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def parse_qos_profiles(text: str) -> list[dict[str, Any]]:
    """The profiles of an ``offered_qos_profiles`` string as dicts (enum names lower case)."""
    if not text or not text.strip():
        return []
    import yaml

    try:
        items = yaml.safe_load(text)
    except yaml.YAMLError:
        return []
    names = {
        "history": {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"},
        "reliability": {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown", 4: "best_available"},
        "durability": {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown", 4: "best_available"},
    }
    result = []
    for item in items if isinstance(items, list) else []:
        if not isinstance(item, dict):
            continue
        for key, table in names.items():
            value = item.get(key)
            if isinstance(value, int):
                item[key] = table.get(value, "unknown")
            elif isinstance(value, str):
                item[key] = value.lower()
        result.append(item)
    return result
