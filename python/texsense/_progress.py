"""Progress bars and the package logger.

Progress bars go to stderr and switch themselves off when stderr is not a terminal; set the
environment variable ``TEXSENSE_NO_PROGRESS=1`` to switch them off everywhere.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

__all__ = ["logger", "progress"]

logger = logging.getLogger("texsense")

T = TypeVar("T")


def progress(
    items: Iterable[T], *, total: int | None = None, desc: str = "", unit: str = "it"
) -> Iterator[T]:
    """Iterate over ``items`` with a progress bar on stderr (if it is a terminal)."""
    disabled: bool | None = True if os.environ.get("TEXSENSE_NO_PROGRESS") else None
    yield from tqdm(items, total=total, desc=desc, unit=unit, disable=disabled, leave=False)
