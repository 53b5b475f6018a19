"""Progress bars, the package logger, and the stop of long loops.

Progress bars go to stderr and switch themselves off when stderr is not a terminal; set the
environment variable ``TEXSENSE_NO_PROGRESS=1`` to switch them off everywhere.

A server that is told to stop sets :data:`STOPPING`; the long loops its worker threads run
(a reader's frames) call :func:`check_stopping` and end, so that a stop never waits for them
and they do not hold the interpreter while it stops.
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

__all__ = ["STOPPING", "StoppingError", "check_stopping", "logger", "progress"]

logger = logging.getLogger("texsense")

#: Set once the process stops (a server's SIGTERM or Ctrl-C); never cleared.
STOPPING = threading.Event()


class StoppingError(RuntimeError):
    """Raised in a worker's long loop once :data:`STOPPING` is set."""


def check_stopping() -> None:
    """Raise :class:`StoppingError` when the process stops (cheap: call it in long loops)."""
    if STOPPING.is_set():
        raise StoppingError("texsense is stopping")


T = TypeVar("T")


def progress(
    items: Iterable[T], *, total: int | None = None, desc: str = "", unit: str = "it"
) -> Iterator[T]:
    """Iterate over ``items`` with a progress bar on stderr (if it is a terminal)."""
    disabled: bool | None = True if os.environ.get("TEXSENSE_NO_PROGRESS") else None
    yield from tqdm(items, total=total, desc=desc, unit=unit, disable=disabled, leave=False)
