"""The force board's frame codec (`hardware/force_board/frame_codec.py`): the boot frame next to the data frames,
and the frames documented in docs/force_board.md decoding as written there."""

from __future__ import annotations

import pytest

from lerobot_blindgrasp.hardware.force_board.frame_codec import (
    Frame,
    FrameParser,
    encode_frame,
    reset_cause_text,
)

COUNTS = (81_000, -52_000, 12_000)


def test_the_documented_frames_decode_as_written():
    data = bytes.fromhex("a55a0f0100683c0100e034ffffe02e0000003b07")  # SEQ 1, docs/force_board.md
    boot = bytes.fromhex("a55a100000683c0100e034ffffe02e000000087489")  # the boot frame after a watchdog reset
    assert encode_frame(1, COUNTS) == data and encode_frame(0, COUNTS, reset_cause=8) == boot
    parser = FrameParser()
    assert parser.feed(data + boot) == [Frame(1, COUNTS, 0), Frame(0, COUNTS, 0, reset_cause=8)]
    assert parser.bad_lengths == parser.crc_errors == 0


@pytest.mark.parametrize("cause, text", [(0x08, "watchdog"), (0x02, "reset pin"), (0x05, "power-on + brown-out"),
                                         (0x00, "unknown (MCUSR 0x00)"), (None, "")])  # fmt: skip
def test_the_reset_cause_is_named(cause, text):
    assert reset_cause_text(cause) == text


def test_a_length_that_is_neither_frame_is_garbage():
    """LEN 4N + 3 is a data frame and 4N + 4 a boot frame; 4N + 5 and 4N + 6 are no frame: dropped, and the next
    SYNC is the next frame."""
    bad = bytearray(encode_frame(3, COUNTS))
    bad[2] += 2
    parser = FrameParser()
    assert parser.feed(bytes(bad) + encode_frame(4, COUNTS)) == [Frame(4, COUNTS, 0)]
    assert parser.bad_lengths == 1
