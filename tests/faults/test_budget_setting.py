"""The memory budget's setting (``TEXSENSE_MAX_MEMORY``) is text from the environment: every
spelling that is no size is one line naming it (harden13: 400 digits were a float of inf and
an ``OverflowError`` traceback out of every reader)."""

from __future__ import annotations

import pytest

from texsense.data.budget import parse_size
from texsense.exceptions import ParameterError

ODD = ["abc", "-1", "0", "1e999", "512Q", "nan", "inf", "0x10", "9" * 400, "9" * 30 + "T", "1" * 20]


@pytest.mark.parametrize("text", ODD)
def test_odd_budget_is_one_error(text: str) -> None:
    with pytest.raises(ParameterError, match="TEXSENSE_MAX_MEMORY"):
        parse_size(text)


@pytest.mark.parametrize(
    ("text", "nbytes"), [("2G", 2 << 30), (" 1.5GiB", 3 << 29), ("4096K", 4 << 20)]
)
def test_sizes_read(text: str, nbytes: int) -> None:
    assert parse_size(text) == nbytes
