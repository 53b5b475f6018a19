"""A value shown in an error message (texsense.exceptions.shown): quoted, and when cut, said
to be cut, so that a long hostile value is never shown as another value (an MQTT payload's
``seq`` of 10**30 used to be named as 10**19). One rule for every message that shows what
it read: the payload's fields, a serial line's numbers, a device's, a reader's line."""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from texsense.data.protocol import ProtocolError, parse_mqtt_payload, parse_serial_line
from texsense.exceptions import shown


@settings(max_examples=300, deadline=None)
@given(text=st.text(max_size=120), limit=st.integers(1, 90))
def test_a_shown_value_is_whole_or_says_it_is_cut(text, limit):
    out = shown(text, limit)
    if len(text) <= limit:
        assert out == repr(text)
    else:
        assert out == f"{text[:limit]!r}... ({len(text)} characters)"
        assert str(len(text)) in out


#: (payload or line, what the message must show of the long value)
LONG = "9" * 31
CASES = [
    ("mqtt", {"seq": int(LONG), "t": 0.0, "values": [1.0, 2.0], "unit": "pF"}),
    ("mqtt", {"seq": "x" * 50, "t": 0.0, "values": [1.0, 2.0], "unit": "pF"}),
    ("mqtt", {"seq": 0, "t": "y" * 50, "values": [1.0, 2.0], "unit": "pF"}),
    ("serial", f"F,{LONG},0,1000,1.0,2.0"),
    ("serial", f"F,1,0,1000,1.0,{'1' * 40}x"),
    ("serial", f"{'G' * 30},1,0,1000,1.0,2.0"),
]


@pytest.mark.parametrize("kind,case", CASES)
def test_a_long_value_in_a_frame_is_said_to_be_cut(kind, case):
    with pytest.raises(ProtocolError) as e:
        if kind == "mqtt":
            parse_mqtt_payload(json.dumps(case).encode(), 2)
        else:
            parse_serial_line(case, 2)
    message = str(e.value)
    assert "characters)" in message and "\n" not in message, message
