"""texsense: open software for textile and other soft pressure sensors.

From raw capacitance to accurate pressure maps: the data model (:class:`Layout`,
:class:`Recording`), readers and writers for real pressure-mapping formats, frame statistics
and a compiled Rust core. See ``docs/`` for one page per capability.

The package's names are imported when first used (so that ``texsense --version`` does not
load the file formats and their libraries). The tree shows the layers, each importing only
from those below it (tests/test_imports.py):

==========================  =============================================================
layer                       packages
==========================  =============================================================
data model and its files    :mod:`texsense.data`, :mod:`texsense.io`
compensation                :mod:`texsense.compensation` (stages, identification, pipeline)
physics and virtual sensor  :mod:`texsense.sensor`, :mod:`texsense.sim` (never the compensation)
calibration                 :mod:`texsense.calibration`
applications                :mod:`texsense.apps` (statistics, clinical, posture, reports)
live products               :mod:`texsense.monitor`, :mod:`texsense.station`
command line                :mod:`texsense.commands`, :mod:`texsense.cli`
==========================  =============================================================
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from texsense import _compat
from texsense._core import __version__

if TYPE_CHECKING:
    from texsense.compensation.pipeline import Pipeline
    from texsense.compensation.stages import StageChain, load_chain
    from texsense.data.layout import Layout
    from texsense.data.recording import Recording
    from texsense.io import load

__all__ = ["Layout", "Pipeline", "Recording", "StageChain", "__version__", "load", "load_chain"]

#: The package's names and the modules that define them.
_LAZY = {
    "Layout": "texsense.data.layout",
    "Recording": "texsense.data.recording",
    "load": "texsense.io",
    "StageChain": "texsense.compensation.stages",
    "load_chain": "texsense.compensation.stages",
    "Pipeline": "texsense.compensation.pipeline",
}

_compat.install()  # the import paths of before the layered tree, for one release


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'texsense' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
