"""MCAP bags the rosbag2 way, without rosbag2: schemas, a crash-tolerant writer, a tolerant reader.

Files written here use profile ``ros2``, schema encoding ``ros2msg`` (the message's
``.msg`` text plus every nested definition, as rosbag2 writes it) and message
encoding ``cdr``; channels carry rosbag2's ``offered_qos_profiles`` metadata. They
open with ``mcap``/``mcap_ros2``, ``rosbags`` (``AnyReader`` on the bare file),
Foxglove and ``ros2 bag`` with the MCAP storage plugin.

Crash tolerance: messages are grouped in zstd-compressed chunks that go to the
operating system as soon as they are complete (no user-space buffering), and
`BagWriter.flush` closes the current chunk early. A process killed with SIGKILL
loses only the chunk in memory; `read_bag` reads every complete chunk of such a
file and then raises `BagError` saying where the file stops.

One module per concern: `errors`, `schemas` (type support), `qos` (QoS metadata),
`writer`, `records` (file access), `reader`, `summary`, `recovery`; the
``recorder`` node (`recorder_node`) and the player `woody replay` drives (`player`).
"""
