"""The memory budget: how much memory texsense may take for what one file or request declares.

A file's header says how big it is (frames, elements, rows x cols, chunk sizes); a hostile or
damaged file can declare far more than it holds (a 10 MB HDF5 of 250,000 frames that are one
repeated compressed chunk, a Tekscan header ``ROWS 3000 COLS 3000``, a layout of 100000 x
100000 cells). Every place that allocates from such a number asks :func:`check` first, with
the bytes it is about to take, and refuses in one line when they exceed the budget; nothing is
allocated from a number the budget has not seen.

The budget is ``TEXSENSE_MAX_MEMORY`` (bytes, or with a suffix ``K``, ``M``, ``G``, ``T``:
``TEXSENSE_MAX_MEMORY=2G``); by default half of the memory this process may use (the
machine's memory, or its control group's limit if lower). Whatever exceeds it is processed in
blocks instead (``texsense process``, :func:`texsense.io.open_reader`), which needs memory
for a block only.

Examples
--------
>>> parse_size("512M")
536870912
>>> check(1024, "a test")           # well within any budget
>>> try:
...     check(1 << 62, "a grid of 2147483648 x 2147483648 cells")
... except ParameterError as e:
...     print(str(e).split(",")[0])
a grid of 2147483648 x 2147483648 cells needs 4096 PiB
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import re
from collections.abc import Iterator
from pathlib import Path

from texsense.exceptions import FormatError, ParameterError, shown

__all__ = ["ENV", "check", "human", "max_memory", "parse_size", "share"]

#: The environment variable that sets the budget.
ENV = "TEXSENSE_MAX_MEMORY"
#: The share of the memory the process may use that is the default budget.
DEFAULT_SHARE = 0.5

_SHARE: contextvars.ContextVar[int | None] = contextvars.ContextVar("budget_share", default=None)
_UNITS = {"": 1, "B": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def parse_size(text: str) -> int:
    """Bytes from ``"4096"``, ``"512M"``, ``"2G"``, ``"1.5GiB"`` (powers of 1024)."""
    m = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]+)?)\s*([KMGT]?)(?:I?B)?\s*", text.upper())
    if not m:
        raise ParameterError(
            f"{ENV}={text!r}: expected a number of bytes, optionally with K, M, G or T"
        )
    amount = float(m.group(1)) * _UNITS[m.group(2)]
    if not amount < 1 << 63:  # 400 digits: a float of inf (int() raised OverflowError)
        raise ParameterError(f"{ENV}={shown(text, 40)}: more bytes than any machine has")
    value = int(amount)
    if value < 1 << 20:
        raise ParameterError(f"{ENV}={text!r}: a budget under 1 MiB leaves nothing to work with")
    return value


def _machine_bytes() -> int:
    """The memory this process may use: physical memory, or its cgroup's limit if lower."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, OSError, ValueError):
        total = 8 << 30
    for limit_file in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(limit_file).read_text().strip()
        except OSError:
            continue
        if text.isdigit() and 0 < int(text) < total:
            total = int(text)
    return int(total)


def max_memory() -> int:
    """The budget in bytes: ``TEXSENSE_MAX_MEMORY`` if set, else half of
    :func:`_machine_bytes`; less inside :func:`share`."""
    text = os.environ.get(ENV)
    whole = parse_size(text) if text else int(_machine_bytes() * DEFAULT_SHARE)
    part = _SHARE.get()
    return whole if part is None else max(0, min(whole, part))


@contextlib.contextmanager
def share(nbytes: int) -> Iterator[None]:
    """Within the block (this thread or task), the budget is at most ``nbytes``: a server
    that already holds some memory (the monitor's cache of recordings) reads the next file
    with what is left."""
    token = _SHARE.set(int(nbytes))
    try:
        yield
    finally:
        _SHARE.reset(token)


def human(nbytes: float) -> str:
    """``1536`` -> ``"1.5 KiB"``."""
    value = float(nbytes)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(value) < 1024:
            return f"{value:.3g} {unit}"
        value /= 1024
    return f"{value:.4g} PiB"


def check(nbytes: float, what: str, path: str | Path | None = None, hint: str = "") -> None:
    """Refuse to allocate ``nbytes`` for ``what`` when they exceed the budget (``hint``: what
    to do instead, appended to the message).

    Raises
    ------
    FormatError
        When ``path`` is given (the file that declares it), naming the file.
    ParameterError
        Otherwise.
    """
    budget = max_memory()
    if nbytes <= budget:
        return
    message = f"{what} needs {human(nbytes)}, more than the memory budget of {human(budget)} "
    message += f"(${ENV})" + (f"; {hint}" if hint else "")
    if path is not None:
        raise FormatError(path, message)
    raise ParameterError(message)
