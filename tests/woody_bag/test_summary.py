"""`woody_bag.summary`: the recorder's losses record (written from per-topic counts, read back, said in one
phrase) and what a bag holds."""

from __future__ import annotations

from woody_bag.reader import read_bag
from woody_bag.summary import (
    LOSSES_RECORD,
    bag_summary,
    losses_record,
    losses_text,
    recorded_losses,
    recording_text,
    unmeasured_text,
    unrecorded_topics,
)
from woody_bag.writer import BagWriter

DROPS = {"/clock": (2292, 2305), "/side_camera/image_raw": (247, 250), "/grading/verdicts": (12, 12),
         "/tf": (5, None)}


def test_losses_travel_through_the_bag_metadata(tmp_path):
    with BagWriter(tmp_path / "x.mcap") as writer:
        writer.add_metadata(LOSSES_RECORD, losses_record(DROPS))
    metadata = bag_summary(tmp_path / "x.mcap")["metadata"]
    assert metadata[LOSSES_RECORD] == {"total": "16", "unmeasured": "/tf", "/clock": "13",
                                       "/side_camera/image_raw": "3"}
    assert recorded_losses(metadata) == {"/clock": 13, "/side_camera/image_raw": 3}
    assert losses_text(recorded_losses(metadata)) == (
        "16 messages lost (/clock 13, /side_camera/image_raw 3)")
    assert unmeasured_text(bag_summary(tmp_path / "x.mcap")) == (
        "; nothing recorded on /tf")  # subscribed, nothing received: no sequence numbers to count losses by
    assert recording_text(bag_summary(tmp_path / "x.mcap")).startswith("0 messages, 16 messages lost (/clock 13")


def test_a_recording_closed_before_any_message_is_complete(tmp_path):
    with BagWriter(tmp_path / "empty.mcap") as writer:
        writer.add_metadata(LOSSES_RECORD, losses_record({}))
    summary = bag_summary(tmp_path / "empty.mcap")
    assert summary["complete"] and summary["message_count"] == 0 and summary["error"] is None
    assert recording_text(summary) == "0 messages, no message lost"
    assert list(read_bag(tmp_path / "empty.mcap")) == []


def test_no_loss_and_no_record_are_told_apart():
    assert recorded_losses({LOSSES_RECORD: losses_record({"/clock": (10, 10)})}) == {}
    assert losses_text({}) == "no message lost"
    assert recorded_losses({"woody": {}}) is None
    assert losses_text(None) == "losses not recorded"


def test_topics_received_nothing_on_are_told_from_topics_of_several_publishers(tmp_path):
    """Both give no count of losses; a topic the recorder subscribed to and got nothing on is named as such."""
    with BagWriter(tmp_path / "x.mcap") as writer:
        writer.add_topic("/tf", "std_msgs/msg/String")
        writer.write("/tf", b"\x00\x01\x00\x00", 1)
        writer.add_metadata(LOSSES_RECORD, losses_record({"/tf": (1, None), "/clock": (0, None)}))
    summary = bag_summary(tmp_path / "x.mcap")
    assert unrecorded_topics(summary) == ["/clock"]
    assert unmeasured_text(summary) == ("; nothing recorded on /clock; losses not measured on /tf (their publishers "
                                        "give no usable sequence numbers)")
    assert recording_text(summary) == ("1 messages, no message lost; nothing recorded on /clock; losses not measured "
                                       "on /tf (their publishers give no usable sequence numbers)")
