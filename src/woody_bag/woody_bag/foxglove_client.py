"""A client of the Foxglove WebSocket protocol, written from the protocol: what a Foxglove app receives from
``foxglove_view`` (tests and `woody bench graph --live` watch the line with it).

Subprotocol ``foxglove.sdk.v1`` (foxglove-sdk's servers; ``foxglove.websocket.v1``, foxglove_bridge's, is
offered too): the server advertises channels in JSON (``advertise``: id, topic,
schemaName, ...), the client subscribes by channel id, and the server sends each message as a binary frame
(opcode 0x01, the uint32 subscription id, the uint64 log time, the payload).

foxglove-sdk 0.30 can advertise a channel created while a client is connected a moment before it accepts
subscriptions to it (measured: 1 channel in 300 answered "Unknown channel ID"); the watcher subscribes
again after ``RETRY_S``, as a user would pick the topic again in Foxglove.
"""

from __future__ import annotations

import asyncio
import json
import re
import struct
import threading
from collections import defaultdict
from pathlib import Path

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01
HEADER = struct.Struct("<BIQ")
"""Opcode, subscription id, log time (ns): what precedes a message's payload."""
UNKNOWN_CHANNEL = re.compile(r"Unknown channel ID: (\d+)")
RETRY_S = 0.05


def served_port(log: Path) -> int | None:
    """The port a ``foxglove_view`` names in its log (``Foxglove view on ws://HOST:PORT``), None before it does."""
    found = re.findall(r"Foxglove view on ws://[^:\s]+:(\d+)", log.read_text()) if log.exists() else []
    return int(found[0]) if found else None


class Watcher:
    """Watches ``topics`` on a Foxglove WebSocket server in a thread until the server closes the connection.

    ``advertised`` maps every advertised topic to its schema name; ``received`` maps each watched topic to
    its messages' payloads (CDR for a ROS 2 server), in arrival order; ``parameter_values`` maps the id of
    each parameter request sent with :meth:`send` to the parameters (name -> value) of the server's answer.
    """

    def __init__(self, url: str, topics: set[str]) -> None:
        self.url, self.topics = url, set(topics)
        self.advertised: dict[str, str] = {}
        self.received: dict[str, list[bytes]] = defaultdict(list)
        self.parameter_values: dict[str, dict[str, object]] = {}
        self.error: BaseException | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._connection = None
        self._thread = threading.Thread(target=self._run, name="foxglove-client", daemon=True)
        self._thread.start()

    def join(self, timeout: float) -> None:
        self._thread.join(timeout)

    def send(self, message: dict) -> bool:
        """Send a JSON message (e.g. ``getParameters``) from any thread; False while not connected."""
        if self._loop is None or self._connection is None:
            return False
        try:
            self._loop.call_soon_threadsafe(self._connection.write_message, json.dumps(message))
        except RuntimeError:  # the connection closed and its loop with it
            return False
        return True

    def _run(self) -> None:
        try:
            asyncio.run(self._watch())
        except Exception as exc:  # noqa: BLE001 - the caller reads it
            self.error = exc

    async def _watch(self) -> None:
        from tornado.websocket import websocket_connect

        connection = await websocket_connect(self.url, subprotocols=SUBPROTOCOLS)
        self._loop, self._connection = asyncio.get_running_loop(), connection
        subscriptions: dict[int, tuple[int, str]] = {}
        while (frame := await connection.read_message()) is not None:
            if isinstance(frame, str):
                await self._on_json(connection, json.loads(frame), subscriptions)
            elif frame[0] == MESSAGE_DATA:
                _, subscription, _ = HEADER.unpack_from(frame)
                self.received[subscriptions[subscription][1]].append(bytes(frame[HEADER.size:]))

    async def _on_json(self, connection, message: dict, subscriptions: dict[int, tuple[int, str]]) -> None:
        """Subscribe each watched topic when it is advertised, and again when the server did not know it yet."""
        if message.get("op") == "status" and (unknown := UNKNOWN_CHANNEL.search(message.get("message", ""))):
            for subscription, (channel_id, _) in subscriptions.items():
                if channel_id == int(unknown.group(1)):
                    await asyncio.sleep(RETRY_S)
                    await _subscribe(connection, subscription, channel_id)
        if message.get("op") == "parameterValues":
            self.parameter_values[message.get("id")] = {p["name"]: p.get("value") for p in message["parameters"]}
        if message.get("op") != "advertise":
            return
        for channel in message["channels"]:
            self.advertised[channel["topic"]] = channel["schemaName"]
            if channel["topic"] in self.topics and channel["topic"] not in {t for _, t in subscriptions.values()}:
                subscription = len(subscriptions) + 1
                subscriptions[subscription] = (channel["id"], channel["topic"])
                await _subscribe(connection, subscription, channel["id"])


async def _subscribe(connection, subscription: int, channel_id: int) -> None:
    await connection.write_message(json.dumps(
        {"op": "subscribe", "subscriptions": [{"id": subscription, "channelId": channel_id}]}))
