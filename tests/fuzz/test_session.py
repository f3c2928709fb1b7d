"""Session logs for `replay`: a real log (60 cycles and their parameters, written by SessionLog)
cut short at every record's edges and at offsets spread over the file, and with bytes flipped. Read
and replayed, each gives a prefix of the original's messages, or one line naming the file, never
another exception (`tests.fuzz.targets`)."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from hoh_cosim.hardware.session_log import read_session
from tests.fuzz.targets import TARGETS, bounded, session_cuts

SESSION = TARGETS["session"]


def test_the_seed_log_is_whole_and_replays(workspace):
    session = read_session(workspace.session_seed)
    assert session.complete
    assert len(session.messages["/robot"]) == 60
    SESSION.check(workspace, workspace.session_seed.read_bytes())


def test_a_log_cut_short_anywhere(workspace):
    data = workspace.session_seed.read_bytes()
    cuts = session_cuts(workspace, 120)
    assert len(cuts) > 150
    for at in cuts:
        SESSION.check(workspace, data[:at])


@bounded(150)
@given(flip=st.data())
def test_a_log_with_bytes_flipped(workspace, flip):
    data = workspace.session_seed.read_bytes()
    at = flip.draw(st.integers(0, len(data) - 1), label="offset")
    mask = flip.draw(st.integers(1, 255), label="mask")
    SESSION.check(workspace, data[:at] + bytes([data[at] ^ mask]) + data[at + 1 :])


@bounded(60)
@given(data=st.data())
def test_a_log_damaged_otherwise(workspace, data):
    """Bytes dropped, inserted or flipped anywhere, as the campaign mutates it."""
    SESSION.check(workspace, data.draw(SESSION.strategy(workspace), label="log"))
