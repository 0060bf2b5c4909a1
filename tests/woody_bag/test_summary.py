"""The recorder's losses record (`woody_bag.summary`): written from per-topic counts, read back, said in one phrase."""

from __future__ import annotations

from woody_bag.summary import LOSSES_RECORD, bag_summary, losses_record, losses_text, recorded_losses
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


def test_no_loss_and_no_record_are_told_apart():
    assert recorded_losses({LOSSES_RECORD: losses_record({"/clock": (10, 10)})}) == {}
    assert losses_text({}) == "no message lost"
    assert recorded_losses({"woody": {}}) is None
    assert losses_text(None) == "losses not recorded"
