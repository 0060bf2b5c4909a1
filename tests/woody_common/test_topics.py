"""woody_common.topics: relative names (a namespace moves them all), each topic once."""

from __future__ import annotations

from rclpy.validate_topic_name import validate_topic_name

from woody_common import topics

NAMES = [value for name, value in vars(topics).items() if name.isupper() and isinstance(value, str)]


def test_every_topic_is_a_valid_relative_name_and_distinct():
    assert len(NAMES) >= 8 and len(set(NAMES)) == len(NAMES)
    for name in NAMES:
        assert not name.startswith("/"), name  # relative: --ros-args -r __ns:=/line2 moves it
        validate_topic_name(name)


def test_tracks_queue_holds_thirty_seconds_of_a_30_hz_camera():
    assert topics.TRACKS_QUEUE_DEPTH == 30 * 30
