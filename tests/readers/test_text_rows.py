"""The readers' fast path for rows of numbers (``texsense._core.parse_row``, Rust) reads every
well-formed row bit for bit as numpy reads its tokens, and refuses every other row (the
reader's own parser then names what is wrong)."""

from __future__ import annotations

import warnings

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from texsense._core import parse_row


def numpy_row(line: str, n: int) -> np.ndarray | None:
    """What the readers' slow path makes of ``line``: n float32 readings, or None."""
    tokens = line.strip().split("\t")
    if len(tokens) != n:
        return None
    try:
        with warnings.catch_warnings(), np.errstate(over="ignore"):
            warnings.simplefilter("ignore")
            return np.array(tokens, dtype=np.float32)
    except ValueError:
        return None


numbers = st.one_of(
    st.integers(-(10**6), 10**7).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.floats(-1e40, 1e40).map(lambda v: f"{v:.9g}"),
    st.floats(-1e3, 1e3).map(lambda v: f" {v:.3f} "),
    st.sampled_from(["1e308", "-1e400", "1e-50", "nan", "inf", "-inf", "+7", "3.", ".5"]),
)
tokens = st.one_of(
    numbers,
    numbers,
    numbers,
    st.sampled_from(["", "abc", "0x10", "1 2", "1,5", "--1", "e5", "1e", "\u0661"]),
)


@settings(max_examples=200, deadline=None)
@given(st.lists(tokens, min_size=1, max_size=12), st.integers(1, 12))
def test_the_fast_path_reads_rows_as_numpy_does(row, n):
    line = "\t".join(row)
    fast = parse_row(line, "\t", n)
    slow = numpy_row(line, n)
    if fast is None:  # refused: the slow path decides (it may read what Rust does not)
        return
    assert slow is not None, line
    assert fast.dtype == np.float32
    np.testing.assert_array_equal(fast.view(np.uint32), slow.view(np.uint32), err_msg=line)


def test_a_pmd_line_and_its_refusals():
    line = "\t".join(str(k % 7) for k in range(2048)) + "\n"
    np.testing.assert_array_equal(parse_row(line, "\t", 2048), np.arange(2048) % 7)
    assert parse_row(line, "\t", 2047) is None
    assert parse_row(line.replace("\t3\t", "\t\t", 1), "\t", 2048) is None
    assert parse_row(line.replace("\t3\t", "\tx\t", 1), "\t", 2048) is None
