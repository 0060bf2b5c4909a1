"""Message types of a bag: rosbag2's ``ros2msg`` schema text, the Python class and CDR decoding.

A schema is the message's ``.msg`` text plus every nested definition, as rosbag2
writes it, read from ``share/<pkg>/msg`` of the ament prefixes (and the venv).
No rclpy node code here: only ``rclpy.serialization`` for `decode`.
"""

from __future__ import annotations

import functools
import importlib
import json
import os
import re
import sys
from pathlib import Path
from typing import Any

SEPARATOR = "=" * 80

_PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
}


def normalize_type(type_name: str) -> str:
    """``pkg/msg/Type`` for ``pkg/msg/Type`` or ``pkg/Type``."""
    parts = type_name.strip().split("/")
    if len(parts) == 2 and all(parts):
        return f"{parts[0]}/msg/{parts[1]}"
    if len(parts) == 3 and all(parts):
        return type_name.strip()
    raise ValueError(f"not a ROS message type name: {type_name!r}")


def _prefixes() -> list[Path]:
    prefixes = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for extra in (sys.prefix, sys.base_prefix):
        if Path(extra) not in prefixes:
            prefixes.append(Path(extra))
    return prefixes


@functools.cache
def _msg_text(pkg: str, name: str) -> str:
    for prefix in _prefixes():
        candidate = prefix / "share" / pkg / "msg" / f"{name}.msg"
        if candidate.is_file():
            return candidate.read_text()
    raise LookupError(f"no {pkg}/msg/{name}.msg under share/ of {os.pathsep.join(map(str, _prefixes()))}")


def _dependencies(pkg: str, text: str) -> list[str]:
    """Complex field types of one .msg text as ``pkg/Type``, sorted."""
    deps: set[str] = set()
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        base = re.sub(r"\[[^\]]*\]$", "", line.split()[0])
        base = re.split(r"<=", base)[0]
        if base in _PRIMITIVES:
            continue
        parts = base.split("/")
        if len(parts) == 1:
            deps.add(f"{pkg}/{parts[0]}")
        else:
            deps.add(f"{parts[0]}/{parts[-1]}")
    return sorted(deps)


@functools.cache
def message_definition(type_name: str) -> str:
    """rosbag2's ``ros2msg`` schema text of ``type_name`` (``pkg/msg/Type`` or ``pkg/Type``)."""
    pkg, _, name = normalize_type(type_name).split("/")
    root = _msg_text(pkg, name)
    written = {f"{pkg}/{name}"}
    blocks: list[str] = [root]

    def visit(dep_pkg: str, text: str) -> None:
        for dep in _dependencies(dep_pkg, text):
            if dep in written:
                continue
            written.add(dep)
            dpkg, dname = dep.split("/")
            dtext = _msg_text(dpkg, dname)
            blocks.append(f"{SEPARATOR}\nMSG: {dep}\n{dtext}")
            visit(dpkg, dtext)

    visit(pkg, root)
    return "\n".join(blocks)


@functools.cache
def type_hash(type_name: str) -> str:
    """The type's ``RIHS01_...`` hash (REP 2011), as rosidl wrote it into ``share/<pkg>/msg/<Type>.json``;
    rosbag2 keeps it as each channel's ``topic_type_hash``. `LookupError` when no such file is installed."""
    full = normalize_type(type_name)
    pkg, kind, name = full.split("/")
    for prefix in _prefixes():
        candidate = prefix / "share" / pkg / kind / f"{name}.json"
        if candidate.is_file():
            hashes = json.loads(candidate.read_text()).get("type_hashes", [])
            for entry in hashes:
                if entry.get("type_name") == full:
                    return str(entry["hash_string"])
    raise LookupError(f"no type hash of {full} under share/ of {os.pathsep.join(map(str, _prefixes()))}")


@functools.cache
def message_class(type_name: str) -> type:
    """The Python class of ``pkg/msg/Type``; `LookupError` (one line) when it cannot be imported."""
    try:
        pkg, kind, name = normalize_type(type_name).split("/")
        module = importlib.import_module(f"{pkg}.{kind}")
        return getattr(module, name)
    except (ImportError, AttributeError, ValueError) as exc:
        raise LookupError(f"message type {type_name} is not importable: {exc}") from None


def decode(type_name: str, data: bytes) -> Any:
    """Deserialize CDR bytes of ``type_name`` into its rclpy message object."""
    from rclpy.serialization import deserialize_message

    return deserialize_message(data, message_class(type_name))
