"""The parameters of every node of the graph, read through the nodes' parameter services (for ``foxglove_view``).

A Foxglove parameters panel asks the server for parameters from the server's own thread and needs the answer at
once; rclpy is not thread-safe, so the node's thread reads them ahead: every ``refresh`` lists each node's
parameters (``<node>/list_parameters``) and then gets their values (``<node>/get_parameters``), without waiting
for an answer; the answers replace the node's values as they come. A node that answered is asked again after
``REREAD_S``; one that did not, after ``ANSWER_WAIT_S``. Names are ``<node>.<parameter>`` (e.g.
``/grader.threshold``), as foxglove_bridge names them.
"""

from __future__ import annotations

import math
import time

from rcl_interfaces.srv import GetParameters, ListParameters
from rclpy.node import Node
from rclpy.parameter import parameter_value_to_python

REREAD_S = 5.0
"""Seconds between two readings of a node's parameters (they are set at start-up and rarely change)."""
ANSWER_WAIT_S = 2.0
"""A node's request is sent again after this long without an answer (a request that reaches a node before it has
matched this node's reply reader gets no reply)."""


class GraphParameters:
    """The latest known parameter values of every other node of the graph, keyed ``<node>.<parameter>``."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.values: dict[str, object] = {}
        """Replaced, never changed in place, so another thread may read it at any time."""
        self._clients: dict[str, tuple] = {}
        self._asked: dict[str, tuple[float, bool]] = {}
        """Node -> when it was last asked (monotonic s) and whether it answered."""

    def refresh(self) -> None:
        """Ask every node that has no request in flight for its parameters."""
        own = self.node.get_fully_qualified_name()
        for name, namespace in self.node.get_node_names_and_namespaces():
            target = f"{namespace.rstrip('/')}/{name}"
            asked, answered = self._asked.get(target, (-math.inf, False))
            if target == own or time.monotonic() - asked < (REREAD_S if answered else ANSWER_WAIT_S):
                continue
            if target not in self._clients:
                self._clients[target] = (self.node.create_client(ListParameters, f"{target}/list_parameters"),
                                         self.node.create_client(GetParameters, f"{target}/get_parameters"))
            listing, _ = self._clients[target]
            if listing.service_is_ready():
                self._asked[target] = (time.monotonic(), False)
                listing.call_async(ListParameters.Request()).add_done_callback(
                    lambda future, target=target: self._on_list(target, future))

    def _on_list(self, target: str, future) -> None:
        names = list(future.result().result.names) if future.result() is not None else []
        _, getting = self._clients[target]
        if not names or not getting.service_is_ready():
            return
        getting.call_async(GetParameters.Request(names=names)).add_done_callback(
            lambda done: self._on_values(target, names, done))

    def _on_values(self, target: str, names: list[str], future) -> None:
        if future.result() is None:
            return
        self._asked[target] = (self._asked[target][0], True)
        fresh = {name: value for name, value in self.values.items() if not name.startswith(f"{target}.")}
        for name, value in zip(names, future.result().values):
            fresh[f"{target}.{name}"] = parameter_value_to_python(value)
        self.values = fresh
