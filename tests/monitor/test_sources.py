import asyncio
import json
import random

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from texsense import Layout, Recording
from texsense.data.protocol import (
    CountError,
    PayloadSizeError,
    ProtocolError,
    format_serial_line,
    parse_mqtt_payload,
    parse_serial_line,
    peek_mqtt_payload,
)
from texsense.exceptions import FormatError, ParameterError
from texsense.monitor import IIOSource, MQTTSource, ReplaySource, SerialSource, VirtualSeatSource


def first(source, n):
    async def go():
        out = []
        async for f in source.frames():
            out.append(f)
            if len(out) == n:
                return out
        return out

    return asyncio.run(go())


def test_serial_line_round_trip_and_errors():
    vals = [1.5, np.nan, 3.25]
    f = parse_serial_line(format_serial_line(7, 2_000_000, 1000, vals), 3)
    assert f.seq == 7
    np.testing.assert_allclose(f.element_times, [2.0, 2.001, 2.002])
    np.testing.assert_array_equal(np.isnan(f.values), [False, True, False])
    assert parse_serial_line("# comment", 3) is None and parse_serial_line("  ", 3) is None
    for line, msg in [
        ("F,1,2,3,1,2", "expected 3 values, got 2"),
        ("F,1,2,3,1,x,2", "value 2 is not a number"),
        ("F,1,2,3,1,inf,2", "not finite"),
        ("G,1,2,3,1,2,3", "unknown record type"),
        ("F,1,2,3,1,2,3*00", "checksum mismatch"),
        ("F,-1,2,3,1,2,3", ">= 0"),
        (b"F,1,2,3,\xff,2,3", "not ASCII"),
    ]:
        with pytest.raises(ProtocolError, match=msg):
            parse_serial_line(line, 3)


def test_mqtt_payload_and_errors():
    f = parse_mqtt_payload(json.dumps({"seq": 1, "t": 2.0, "dt": 0.5, "values": [1, None]}), 2)
    fast = parse_mqtt_payload(json.dumps({"seq": 1, "t": 2.0, "values": [1, 2.5]}), 2)
    np.testing.assert_array_equal(fast.values, [1.0, 2.5])
    np.testing.assert_allclose(f.element_times, [2.0, 2.5])
    assert np.isnan(f.values[1]) and f.unit == "pF"
    for payload, msg in [
        (b"{", "not JSON"),
        (b"[]", "JSON object"),
        (json.dumps({"t": 1, "values": [1, 2]}), "lacks 'seq'"),
        (json.dumps({"seq": 1, "t": 1, "values": [1]}), "list of 2"),
        (json.dumps({"seq": 1, "t": 1, "values": [1, "a"]}), "value 2"),
        (json.dumps({"seq": 1, "t": 1, "values": [1, "2.5"]}), "value 2"),  # no number as text
        (json.dumps({"seq": 1, "t": 1, "values": [True, 2]}), "value 1"),
        ('{"seq": 1, "t": 1, "values": [1, 1e999]}', "value 2"),  # infinite
        (json.dumps({"seq": 1, "t": 1, "values": [1, 2], "unit": "furlong"}), "unknown unit"),
        (json.dumps({"seq": 1, "t": 1, "values": [1, 2], "unit": "mm"}), "neither"),
        (json.dumps({"seq": True, "t": 1, "values": [1, 2]}), "'seq'"),
    ]:
        with pytest.raises(ProtocolError, match=msg):
            parse_mqtt_payload(payload, 2)


def test_a_payload_peeked_gives_what_its_parse_gives_or_says_to_parse_it():
    """A skipped frame's time without its values (peek_mqtt_payload): the parse's seq and t,
    its count checked; anything not of the plain form or of another count is left to the
    full parse (None), which says what is wrong (a list that is not JSON, or its count)."""
    plain = json.dumps({"seq": 1, "t": 1e9, "values": [1e-3, 2, -4]}).encode()
    for payload in [json.dumps({"seq": 7, "t": 2.5, "values": [1, None, 3.0]}),
                    '{"values" : [ 1,2 ,3 ], "unit": "pF", "t": 4, "seq": 0}', plain]:  # fmt: skip
        f = parse_mqtt_payload(payload, 3)
        assert peek_mqtt_payload(payload, 3) == (f.seq, f.t)
    assert peek_mqtt_payload(json.dumps({"seq": 1, "t": 1, "values": [1, 2]}), 3) is None
    assert peek_mqtt_payload(b'{"seq": 0, "t": 0, "values": [2,00.0]}', 3) is None
    with pytest.raises(ProtocolError, match="not JSON"):  # not a count of 2
        parse_mqtt_payload(b'{"seq": 0, "t": 0, "values": [2,00.0]}', 3)
    with pytest.raises(PayloadSizeError):
        peek_mqtt_payload(b" " * 100, 3, max_bytes=50)
    for payload in ['{"unit": "values", "seq": 1, "t": 1, "values": [1, 2, 3]}',
                    '{"seq": 1, "t": 1, "values": [[1], 2, 3]}', '{"seq": 1, "t": 1}',
                    '{"seq": true, "t": 1, "values": [1, 2, 3]}', '{"seq": 1, "values": [1,2,3]',
                    '{"seq": 1, "t": "1", "values": [1, 2, 3]}']:  # fmt: skip
        assert peek_mqtt_payload(payload, 3) is None, payload


def random_line(rng):
    kind = rng.random()
    if kind < 0.2:
        return bytes(rng.getrandbits(8) for _ in range(rng.randrange(0, 80)))
    good = format_serial_line(rng.randrange(100), rng.randrange(10**6), 500, [1.0, 2.0, 3.0])
    chars = list(good)
    for _ in range(rng.randrange(1, 4)):  # mutate a few characters
        i = rng.randrange(len(chars))
        chars[i] = rng.choice(",*F-.e0123456789abc \t")
    return "".join(chars).encode()


class FakeSerial:
    """A pySerial-like device fed from a list of lines."""

    def __init__(self, lines):
        self.lines = list(lines)

    def readline(self):
        if not self.lines:
            raise EOFError
        return self.lines.pop(0) + b"\n"

    def close(self):
        pass


def test_fuzzed_serial_lines_are_counted_and_skipped_and_good_frames_pass():
    rng = random.Random(0)
    lines = []
    for k in range(3000):
        lines.append(random_line(rng))
        if k % 100 == 0:
            lines.append(format_serial_line(k, k * 1000, 10, [1.0, 2.0, 3.0]).encode())
    src = SerialSource("fake", Layout.grid(1, 3), opener=lambda *a, **k: FakeSerial(lines))
    frames = []
    with pytest.raises(EOFError):  # the fake device ends; the source never stopped before

        async def go():
            async for f in src.frames():
                frames.append(f)

        asyncio.run(go())
    assert src.lines == len(lines)
    good = [f for f in frames if f.element_times[1] - f.element_times[0] == pytest.approx(1e-5)]
    assert len(good) == 30  # every well-formed frame came through
    assert src.errors >= 2800 and src.errors + len(frames) <= src.lines  # some mutants stay valid
    assert src.last_error.startswith("line ")


def test_serial_source_over_a_pyserial_loop_url():
    src = SerialSource("loop://", Layout.grid(1, 2))
    src._dev.write((format_serial_line(1, 0, 100, [5.0, 6.0]) + "\ngarbage\n").encode())
    (f,) = first(src, 1)
    assert f.values.tolist() == [5.0, 6.0]
    src.close()


def test_fuzzed_mqtt_payloads_are_counted_and_skipped():
    rng = random.Random(1)
    src = MQTTSource("localhost", Layout.grid(1, 2))
    ok = 0
    for k in range(2000):
        good = json.dumps({"seq": k, "t": k * 0.1, "values": [1.0, 2.0], "unit": "pF"})
        if k % 10 == 0:
            ok += src.handle(good.encode()) is not None
            continue
        chars = list(good)
        for _ in range(rng.randrange(1, 4)):
            chars[rng.randrange(len(chars))] = rng.choice('{}[],:"0123456789.eanul ')
        src.handle("".join(chars).encode())
    assert ok == 200 and src.messages == 2000 and src.errors >= 1500
    kpa = src.handle(json.dumps({"seq": 1, "t": 0, "values": [1, 2], "unit": "kPa"}).encode())
    assert kpa is None  # a pressure payload on a capacitance source is refused


def test_iio_source_reads_a_sysfs_tree_through_a_multiplexer(tmp_path):
    dev = tmp_path / "iio:device0"
    dev.mkdir()
    (dev / "in_capacitance0_raw").write_text("1000\n")
    (dev / "in_capacitance0_scale").write_text("0.000000488\n")  # ad7746: 8.192 pF / 2^24
    (dev / "in_capacitance0_offset").write_text("0\n")
    (dev / "sampling_frequency").write_text("91\n")
    selected = []

    def mux(i):
        selected.append(i)
        (dev / "in_capacitance0_raw").write_text(f"{1_000_000 * (i + 1)}\n")

    src = IIOSource(dev, Layout.grid(1, 3), multiplexer=mux, sampling_frequency=45.5, capdac_pF=5.0)
    offset = round(5.0 / 0.000000488)
    assert (dev / "in_capacitance0_offset").read_text() == str(offset)  # the CAPDAC
    (f,) = first(src, 1)
    assert selected == [0, 1, 2]
    expected = [(1_000_000 * k + offset) * 0.000000488 for k in (1, 2, 3)]
    np.testing.assert_allclose(f.values, expected)  # 5.49, 5.98, 6.46 pF
    assert (dev / "sampling_frequency").read_text() == "45.5"
    assert np.all(np.diff(f.element_times) >= 0)
    (dev / "in_capacitance0_raw").write_text("garbage")
    src.mux = None
    src.channels = [0, 0, 0]
    _times, values = src.read_frame()
    assert np.all(np.isnan(values)) and src.errors == 3
    with pytest.raises(FormatError, match="in_capacitance5_raw"):
        IIOSource(dev, Layout.grid(1, 1), channels=[5])


def test_replay_source_yields_the_recording_and_loops():
    rec = Recording(
        np.arange(6.0).reshape(3, 2), [0.0, 0.5, 1.0], Layout.grid(1, 2), "pressure", "N/cm2"
    )
    frames = first(ReplaySource(rec, speed=0, loop=True), 5)
    assert [f.values[0] for f in frames] == [0.0, 2.0, 4.0, 0.0, 2.0]
    assert [f.t for f in frames] == [0.0, 0.5, 1.0, 1.5, 2.0]


def test_virtual_seat_source_gives_capacitance_with_failures():
    src = VirtualSeatSource(speed=0, hold_s=10, postures_per_sitting=2, away_s=5)
    frames = first(src, 30)
    assert src.layout.n_elements == 96 and src.quantity == "capacitance"
    v = np.array([f.values for f in frames])
    assert np.all(np.isfinite(v)) and (v == 0).any()  # dead elements read 0 pF
    t = np.array([f.t for f in frames])
    assert np.all(np.diff(t) > 0)


def test_virtual_bed_source_turns_and_leaves_the_bed():
    from texsense.monitor.virtual import VirtualBedSource

    src = VirtualBedSource(speed=0, hold_s=3, positions_per_stay=3, away_s=3, seed=1)
    seen = []
    frames = []
    for f in first_with(src, 40, lambda: seen.append(src.side)):
        frames.append(f)
    assert src.layout.n_elements == 2048 and src.layout.shape == (64, 32)
    sides = set(seen) - {None, "transition"}
    assert len(sides) >= 3 and "transition" in seen and None in seen  # turns, gets up
    v = np.array([f.values for f in frames])
    assert np.all(np.isfinite(v)) and np.all(np.diff([f.t for f in frames]) > 0)
    # lying changes the capacitance under the body, an empty bed does not
    lying = v[[k for k, p in enumerate(seen) if p]].mean(axis=0)
    empty = v[[k for k, p in enumerate(seen) if p is None]].mean(axis=0)
    assert np.max(lying - empty) > 0.2


def first_with(source, n, each):
    """The first n frames of a source, calling ``each()`` after every one."""

    async def go():
        out = []
        async for f in source.frames():
            each()
            out.append(f)
            if len(out) >= n:
                break
        return out

    return asyncio.run(go())


def test_replay_source_refuses_what_it_cannot_monitor():
    lay = Layout.grid(1, 2)
    raw = Recording(np.ones((2, 2)), [0.0, 1.0], lay, "raw", "count")
    with pytest.raises(ParameterError, match=r"needs capacitance .* or pressure"):
        ReplaySource(raw)
    empty = Recording(np.ones((0, 2)), np.zeros(0), lay, "pressure", "N/cm2")
    with pytest.raises(ParameterError, match="no frames"):
        ReplaySource(empty)
    with pytest.raises(ParameterError, match="speed"):
        ReplaySource(Recording(np.ones((1, 2)), [0.0], lay, "pressure", "N/cm2"), speed=-1)


def test_cli_iio_source_with_a_multiplexer_from_a_file(tmp_path):
    from texsense.cli import build_parser
    from texsense.commands.monitor import open_source

    dev = tmp_path / "iio:device0"
    dev.mkdir()
    (dev / "in_capacitance0_raw").write_text("0\n")
    (dev / "in_capacitance_scale").write_text("0.000000488\n")
    (dev / "in_capacitance0_offset").write_text("0\n")
    mux = tmp_path / "mymux.py"
    mux.write_text(
        "from pathlib import Path\n"
        f"RAW = Path({str(dev / 'in_capacitance0_raw')!r})\n"
        "def select(i):\n"
        "    RAW.write_text(str(1_000_000 * (i + 1)))\n"
    )
    args = build_parser(["monitor"]).parse_args(
        ["monitor", f"--source=iio:{dev}", "--grid", "1x2", "--multiplexer", f"{mux}:select"]
    )
    src = open_source(args)
    _times, values = src.read_frame()
    np.testing.assert_allclose(values, [0.488, 0.976])
    for bad, what in [
        (f"{mux}:nothing", "no function 'nothing'"),
        (f"{tmp_path / 'none.py'}:f", "no such file"),
        ("texsense_no_such_module:f", "cannot import"),
        ("select", "expected MODULE:FUNCTION"),
    ]:
        args.multiplexer = bad
        with pytest.raises(ParameterError, match=what):
            open_source(args)


_KEYS = st.sampled_from(["seq", "t", "values", "unit", "note", "vals", "value"])
_SCALARS = st.one_of(
    st.none(), st.booleans(), st.integers(-5, 2**40), st.floats(allow_nan=False),
    st.text(max_size=8),
)  # fmt: skip


@st.composite
def _payloads(draw: st.DrawFn) -> bytes:
    """Plain payloads, payloads with odd keys and values, and their bytes cut or spliced."""
    d = {"seq": draw(st.integers(-2, 2**40)), "t": draw(_SCALARS | st.floats(0, 1e10))}
    d["values"] = draw(st.lists(_SCALARS | st.floats(-1e3, 1e3), min_size=0, max_size=5))
    for key in draw(st.lists(_KEYS, max_size=3)):
        d[key] = draw(_SCALARS | st.lists(_SCALARS, max_size=3))
    b = json.dumps(d).encode()
    if draw(st.booleans()):
        i = draw(st.integers(0, len(b)))
        j = draw(st.integers(i, len(b)))
        b = b[:i] + draw(st.sampled_from([b"", b"[", b"]", b'"', b",", b"{", b'"values"'])) + b[j:]
    return b


@settings(max_examples=300, deadline=None)
@given(_payloads())
def test_a_peek_never_disagrees_with_the_parse(payload):
    """Generated payloads: a peek that answers gives the parse's seq and t (when the parse
    accepts the frame: a skipped frame's values are not judged), an error it raises is the
    parse's, and anything it cannot vouch for it leaves to the parse (None)."""
    try:
        peeked = peek_mqtt_payload(payload, 3)
    except (CountError, PayloadSizeError) as e:
        with pytest.raises(type(e)):
            parse_mqtt_payload(payload, 3)
        return
    try:
        frame = parse_mqtt_payload(payload, 3)
    except CountError:
        assert peeked is None, (payload, peeked)  # a wrong count is left to the parse
        return
    except ProtocolError:
        return
    assert peeked is None or peeked == (frame.seq, frame.t), (payload, peeked)


_NUMBERS = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False).map(repr),
    st.integers(-(2**70), 2**70).map(str),
    st.sampled_from(["null", "-0", "-0.0", "0e0", "1E+2", "2.5e-3", "-1.5E-300", "4.9e-324"]),
)  # fmt: skip
_ODD = st.sampled_from(["1e400", "-1e400", "NaN", "Infinity", "01", "1.", ".5", "+1", "true",
                        '"1"', "1e", "0x1", "", "[1]", "{}"])  # fmt: skip
_EXTRA = st.sampled_from([
    ',"unit":"pF"', ',"unit":"kPa"', ',"unit":"V"', ',"unit":3', ',"dt":0.001', ',"dt":-1',
    ',"element_times":[0,1,2]', ',"element_times":[0,1]', ',"values":[1,2,3]', ',"values":false',
    ',"values":0', ',"\\u0076alues":[4,5,6]', ',"\\u0076alues":0', ',"note":"a\\"values\\":[1]"',
    ',"x":{"values":[1]}', ',"note":"\\u00e9t\u00e9"', ',"note":"été"',
])  # fmt: skip


@st.composite
def _value_payloads(draw: st.DrawFn) -> bytes:
    """Payloads of three values written as JSON writes numbers, and (each now and then) as it
    does not, another count, odd seq and t, odd keys after them, a BOM or a byte in front, and
    their bytes cut or spliced."""
    odd = lambda: draw(st.integers(0, 5)) == 0  # noqa: E731
    tokens = draw(st.lists(_NUMBERS, min_size=3, max_size=3))
    if odd():
        tokens[draw(st.integers(0, 2))] = draw(_ODD)
    if odd():
        tokens = tokens[: draw(st.sampled_from([0, 2]))] + (["5"] if odd() else [])
    space = draw(st.sampled_from(["", " ", "\n\t", "\r "] + (["\x0b"] if odd() else [])))
    seq = draw(st.sampled_from(["-1", "true", "1.5", '"7"'])) if odd() else "7"
    t = draw(st.sampled_from(["null", "1e999", '"1"'])) if odd() else "12.25"
    text = draw(st.sampled_from(['{{"seq":{s},"t":{t},"values":{v}{x}}}',
                                 '{{"values" :{v},"t":{t},"seq":{s}{x}}}']))  # fmt: skip
    if odd():
        text = draw(st.sampled_from(['{{"t":{t},"values":{v}{x}}}', "[{v}]"]))
    values = "[" + space + ("," + space).join(tokens) + space + "]"
    b = text.format(s=seq, t=t, v=values, x=draw(_EXTRA) if odd() else "").encode()
    if odd():
        b = draw(st.sampled_from([b"\xef\xbb\xbf", b" ", b"\xff"])) + b
    if odd():
        i = draw(st.integers(0, len(b)))
        j = draw(st.integers(i, min(i + 3, len(b))))
        b = b[:i] + draw(st.sampled_from([b"", b"[", b"]", b'"', b",", b"{", b"\\"])) + b[j:]
    return b


@settings(max_examples=400, deadline=None)
@given(_value_payloads())
def test_the_compiled_values_read_gives_the_whole_parse_frame_or_its_error(payload):
    """Generated payloads: parse_mqtt_payload (values read by the compiled core where the
    payload is plain) gives exactly the frame of the parse by json alone (seq, t, unit, element
    times, every value to the bit, NaN for null, the sign of a zero), or its error, the same
    class and line."""
    from texsense.data.protocol import _parse_whole

    try:
        want = _parse_whole(payload, 3)
    except ProtocolError as e:
        with pytest.raises(type(e)) as got:
            parse_mqtt_payload(payload, 3)
        assert str(got.value) == str(e) and "\n" not in str(e)
        return
    frame = parse_mqtt_payload(payload, 3)
    assert (frame.seq, frame.t, frame.unit) == (want.seq, want.t, want.unit)
    np.testing.assert_array_equal(frame.element_times, want.element_times)
    assert frame.values.dtype == np.float64
    assert frame.values.tobytes() == want.values.tobytes(), (payload, frame.values, want.values)


def test_plain_payloads_take_the_compiled_values_read():
    """The station's payloads are of the plain form: their values are read by the compiled
    core, not by json (what makes the parse cheap), to the same numbers."""
    import texsense.data.protocol as protocol

    payload = json.dumps({"seq": 3, "t": 1.5, "values": [0.1, -2, None, 1e-7], "unit": "pF"})
    whole = protocol._parse_whole
    try:
        protocol._parse_whole = None  # type: ignore[assignment]  (not reached)
        frame = protocol.parse_mqtt_payload(payload.encode(), 4)
    finally:
        protocol._parse_whole = whole
    np.testing.assert_array_equal(frame.values, [0.1, -2.0, np.nan, 1e-7])
    assert (frame.seq, frame.t, frame.unit) == (3, 1.5, "pF")


@pytest.mark.parametrize(
    "payload",
    [
        b'{"seq":3,"t":1764329000.123456,"values":[0.1,-2,null,1e-7],"unit":"pF"}',
        b'{ "values" : [1, 2, 3, 4] , "dt": 0.25, "unit": "kPa", "t": -0, "seq": 0 }',
        b'{"seq":9223372036854775807,"t":5,"values":[1,2,3,4],"dt":0}',
    ],
)
def test_the_payloads_mats_send_are_read_whole_by_the_compiled_core(payload):
    """A payload of the plain form (seq, t, values, unit, dt: what mats send) is read in one
    compiled call, neither by json nor by the splice of its values list, to the frame the
    parse by json alone gives."""
    import texsense.data.protocol as protocol

    want = protocol._parse_whole(payload, 4)
    splice, whole = protocol._splice, protocol._parse_whole
    try:
        protocol._splice = protocol._parse_whole = None  # type: ignore[assignment]
        frame = protocol.parse_mqtt_payload(payload, 4)
    finally:
        protocol._splice, protocol._parse_whole = splice, whole
    assert (frame.seq, frame.t, frame.unit) == (want.seq, want.t, want.unit)
    assert frame.element_times.tobytes() == want.element_times.tobytes()
    assert frame.values.tobytes() == want.values.tobytes()
