"""The FT-150 stream parser and the daemon's sample format (src/hoh_cosim/hardware/ft150.py)."""

from __future__ import annotations

import math
from itertools import pairwise

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hoh_cosim.errors import ConfigError
from hoh_cosim.hardware.ft150 import MAX_FRAME_BYTES, FT150Parser, encode_sample

S1 = b"( -0.39 , 1.46 , -1.25 , 0.007 , -0.011 , 0.002 )"
V1 = [-0.39, 1.46, -1.25, 0.007, -0.011, 0.002]
S2 = b"( 12.50 , -3.00 , 40.25 , -1.250 , 0.500 , 0.000 )"
V2 = [12.5, -3.0, 40.25, -1.25, 0.5, 0.0]


def parse(*chunks: bytes) -> tuple[list[list[float]], FT150Parser]:
    parser = FT150Parser()
    out = []
    for chunk in chunks:
        out += [s.tolist() for s in parser.feed(chunk)]
    return out, parser


def as_sent(values) -> list[float]:
    """What the parser must read back for `values` written by encode_sample."""
    return [float(f"{x:.2f}") for x in values[:3]] + [float(f"{x:.3f}") for x in values[3:]]


def test_exact_values():
    samples, parser = parse(S1 + S2)
    assert samples == [V1, V2]
    assert (parser.frames, parser.bad_frames, parser.pending) == (2, 0, 0)


def test_samples_are_float_arrays_of_six():
    (sample,) = FT150Parser().feed(S1)
    assert sample.shape == (6,)
    assert sample.dtype == np.float64


@pytest.mark.parametrize(
    ("text", "value"),
    [
        (b"-0.39", -0.39),
        (b"1e-3", 1e-3),
        (b"+2", 2.0),
        (b".5", 0.5),
        (b"5.", 5.0),
        (b"-1.5E+2", -150.0),
        (b"0.000000", 0.0),  # the C driver's printf("%f")
        (b"-12.345678", -12.345678),
    ],
)
def test_number_forms(text, value):
    samples, parser = parse(b"( " + text + b" , 0 , 0 , 0 , 0 , 0 )")
    assert samples == [[value, 0.0, 0.0, 0.0, 0.0, 0.0]]
    assert parser.bad_frames == 0


def test_whitespace_and_line_endings_inside_a_frame_are_fine():
    samples, _ = parse(b"(-0.39,1.46 ,\t-1.25 ,\r\n0.007, -0.011 , 0.002)")
    assert samples == [V1]


def test_split_at_every_byte_offset_gives_the_same_samples():
    stream = S1 + S2
    for cut in range(len(stream) + 1):
        samples, parser = parse(stream[:cut], stream[cut:])
        assert samples == [V1, V2], f"cut at byte {cut}"
        assert parser.bad_frames == 0


def test_split_at_every_pair_of_offsets_gives_the_same_samples():
    stream = S1 + S2
    for a in range(len(stream) + 1):
        for b in range(a, len(stream) + 1):
            samples, parser = parse(stream[:a], stream[a:b], stream[b:])
            assert samples == [V1, V2], f"cuts at bytes {a} and {b}"
            assert parser.bad_frames == 0


def test_byte_by_byte():
    stream = S1 + S2
    samples, _ = parse(*(stream[i : i + 1] for i in range(len(stream))))
    assert samples == [V1, V2]


def test_a_sample_is_returned_by_the_feed_that_completes_it():
    parser = FT150Parser()
    assert parser.feed(S1[:-1]) == []
    assert parser.pending == len(S1) - 1
    (sample,) = parser.feed(b")")
    assert sample.tolist() == V1
    assert parser.pending == 0


def test_garbage_before_and_between_samples_is_skipped():
    samples, parser = parse(
        b"\x00\xff\r\nhello ) , 3.0 ," + S1 + b"\n junk ) 1 , 2 " + S2 + b"tail"
    )
    assert samples == [V1, V2]
    assert parser.bad_frames == 0
    assert parser.pending == 0


@pytest.mark.parametrize(
    "frame",
    [
        b"( 1 , 2 , 3 , 4 , 5 )",
        b"( 1 , 2 , 3 , 4 , 5 , 6 , 7 )",
        b"( )",
        b"()",
        b"( 1 , 2 , x , 4 , 5 , 6 )",
        b"( 1 , , 3 , 4 , 5 , 6 )",
        b"( 1 2 , 3 , 4 , 5 , 6 , 7 )",
        b"( 1 , 2 , 3 , 4 , 5 , 6 , )",
        b"( 1.2.3 , 2 , 3 , 4 , 5 , 6 )",
        b"( 1_0 , 2 , 3 , 4 , 5 , 6 )",  # float() would take it; the daemon never sends it
        b"( 0x10 , 2 , 3 , 4 , 5 , 6 )",
    ],
)
def test_a_frame_that_is_not_six_numbers_is_bad_and_parsing_recovers(frame):
    samples, parser = parse(S1 + frame + S2)
    assert samples == [V1, V2]
    assert parser.bad_frames == 1
    assert parser.frames == 2


def test_a_frame_cut_short_by_the_next_one_is_bad():
    # the daemon's stream lost the end of a sample: `(` ... `(` ... `)`
    samples, parser = parse(S1 + b"( 1.00 , 2.0" + S2)
    assert samples == [V1, V2]
    assert parser.bad_frames == 1


def test_a_frame_cut_short_is_counted_once_however_it_is_split():
    stream = S1 + b"( 1.00 , 2.0" + S2
    for cut in range(len(stream) + 1):
        samples, parser = parse(stream[:cut], stream[cut:])
        assert samples == [V1, V2], f"cut at byte {cut}"
        assert parser.bad_frames == 1, f"cut at byte {cut}"


@pytest.mark.parametrize("text", [b"nan", b"NaN", b"-nan", b"inf", b"-inf", b"+Infinity"])
def test_non_finite_numbers_are_passed_through(text):
    samples, parser = parse(b"( 1 , " + text + b" , 3 , 4 , 5 , 6 )")
    (sample,) = samples
    assert parser.bad_frames == 0
    assert sample[0] == 1.0
    assert sample[2:] == [3.0, 4.0, 5.0, 6.0]
    assert not math.isfinite(sample[1])
    assert math.isnan(sample[1]) == (b"nan" in text.lower())
    if math.isinf(sample[1]):
        assert (sample[1] < 0) == text.startswith(b"-")


def test_unbounded_junk_without_a_closing_bracket_is_bounded():
    parser = FT150Parser()
    assert parser.feed(b"( 1.00 , ") == []
    for _ in range(200):
        assert parser.feed(b"7" * 1000) == []
        assert parser.pending <= MAX_FRAME_BYTES
    assert parser.bad_frames == 1  # one dropped run, not one per read
    (sample,) = parser.feed(b" ) , 2 ) " + S1)
    assert sample.tolist() == V1
    assert parser.bad_frames == 1


def test_an_overlong_frame_is_bad_whether_split_or_whole():
    frame = b"( 1" + b"0" * MAX_FRAME_BYTES + b" , 2 , 3 , 4 , 5 , 6 )"
    for cut in (len(frame), 100, MAX_FRAME_BYTES + 50):  # whole; split before; after the limit
        samples, parser = parse(frame[:cut], frame[cut:] + S1)
        assert samples == [V1], f"cut at byte {cut}"
        assert parser.bad_frames == 1, f"cut at byte {cut}"


def test_junk_without_an_opening_bracket_is_not_held():
    parser = FT150Parser()
    for _ in range(100):
        parser.feed(b"x) 1 , 2 , 3 \r\n" * 100)
        assert parser.pending == 0
    assert parser.bad_frames == 0


def test_empty_feed():
    parser = FT150Parser()
    assert parser.feed(b"") == []
    parser.feed(S1[:5])
    assert parser.feed(b"") == []
    assert parser.pending == 5


def test_encode_sample_writes_the_daemons_format():
    assert encode_sample(V1) == S1
    assert encode_sample(np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])) == (
        b"( 0.00 , 0.00 , 0.00 , 0.000 , 0.000 , 0.000 )"
    )
    # forces to 2 decimals, torques to 3
    assert encode_sample([1.005, 2.4449, -3.0, 0.0005, 0.12345, -7]) == (
        b"( 1.00 , 2.44 , -3.00 , 0.001 , 0.123 , -7.000 )"
    )


def test_encode_sample_writes_non_finite_values_as_text():
    assert encode_sample([math.nan, math.inf, -math.inf, 1, 2, 3]) == (
        b"( nan , inf , -inf , 1.000 , 2.000 , 3.000 )"
    )


@pytest.mark.parametrize("n", [0, 5, 7])
def test_encode_sample_rejects_a_wrong_count(n):
    with pytest.raises(ConfigError, match=rf"^encode_sample: expected 6 values .*, got {n}$"):
        encode_sample([1.0] * n)


force = st.floats(-1e4, 1e4, allow_nan=False)
torque = st.floats(-1e3, 1e3, allow_nan=False)
sample = st.tuples(force, force, force, torque, torque, torque)


@given(sample)
def test_encode_sample_round_trips_through_the_parser(values):
    samples, parser = parse(encode_sample(values))
    assert samples == [as_sent(values)]
    assert parser.bad_frames == 0


@given(
    st.lists(sample, min_size=1, max_size=8),
    st.lists(st.integers(0, 2000), max_size=10),
    st.lists(st.binary(max_size=12).map(lambda b: b.replace(b"(", b"").replace(b")", b""))),
)
def test_any_splitting_and_garbage_between_gives_the_samples_in_order(values, cuts, junk):
    stream = b""
    for i, v in enumerate(values):
        stream += (junk[i] if i < len(junk) else b"") + encode_sample(v)
    bounds = sorted({min(c, len(stream)) for c in cuts} | {0, len(stream)})
    samples, parser = parse(*(stream[a:b] for a, b in pairwise(bounds)))
    assert samples == [as_sent(v) for v in values]
    assert parser.bad_frames == 0
    assert parser.pending == 0


@given(st.lists(st.sampled_from([math.nan, math.inf, -math.inf, 0.25]), min_size=6, max_size=6))
def test_non_finite_values_round_trip(values):
    ((got,), _) = parse(encode_sample(values))
    np.testing.assert_array_equal(got, values)  # nan equals nan here
