"""The FT-150 stream parser and the FSE103 frame parser against garbage and any chunking: the
invariants of `tests.fuzz.targets` (never raise, chunking changes nothing, bounded pending bytes,
the valid data back in order), on a fixed sample of inputs.

tests/unit/test_*_parser.py hold the exact behaviour; these add garbage with brackets, start and end
bytes and partial frames between valid data, the given framings and byte orders, and chunking."""

from __future__ import annotations

from hypothesis import example, given

from tests.fuzz.targets import TARGETS, bounded

FT150 = TARGETS["ft150"]
FSE103 = TARGETS["fse103"]


@bounded(300)
@given(value=FT150.strategy(None))
@example(value=((b"(" + b"7" * 600,), (1,)))  # a frame longer than MAX_FRAME_BYTES, fed bytewise
@example(value=((b") 1, 2, 3, 4, 5, 6 (", b"(1,2,3,4,5,6)"), (5, 3)))  # brackets in the garbage
def test_ft150_samples_come_back_whatever_the_garbage_and_chunking(workspace, value):
    FT150.check(workspace, value)


@bounded(300)
@given(value=FSE103.strategy(None))
# a cut frame completed by the next frame's first bytes into a plausible one, taken in sync
@example(value=((b"\x00\x1c\x00\x00\x00\x00J\x01\x00\x00\x00\x00\x00\x00\x00",), (2,), "seed18", "little", False, 0))  # fmt: skip
@example(value=((b"\x0d\x14\x66\x00", b"\xff" * 40), (), "guide20", "big", True, 2))
def test_fse103_frames_come_back_whatever_the_garbage_and_chunking(workspace, value):
    FSE103.check(workspace, value)


def test_the_parsers_decode_raw_bytes_for_the_campaign(workspace):
    """atheris' raw bytes make inputs the same checks take (a smoke test of the decoders)."""
    for target in (FT150, FSE103):
        for data in (b"", b"\x07", bytes(range(256)), *target.corpus(workspace)):
            target.check(workspace, target.decode(data))
