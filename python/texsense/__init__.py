"""texsense: open software for textile and other soft pressure sensors.

From raw capacitance to accurate pressure maps: the data model (:class:`Layout`,
:class:`Recording`), readers and writers for real pressure-mapping formats, frame statistics
and a compiled Rust core. See ``docs/`` for one page per capability.

``Layout``, ``Recording`` and ``load`` are imported when first used (so that ``texsense
--version`` does not load the file formats and their libraries).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from texsense._core import __version__

if TYPE_CHECKING:
    from texsense.io import load
    from texsense.layout import Layout
    from texsense.recording import Recording

__all__ = ["Layout", "Recording", "__version__", "load"]

#: The package's names and the modules that define them.
_LAZY = {"Layout": "texsense.layout", "Recording": "texsense.recording", "load": "texsense.io"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'texsense' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
