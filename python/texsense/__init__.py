"""texsense: open software for textile and other soft pressure sensors.

From raw capacitance to accurate pressure maps: the data model (:class:`Layout`,
:class:`Recording`), readers and writers for real pressure-mapping formats, frame statistics
and a compiled Rust core. See ``docs/`` for one page per capability.
"""

from texsense._core import __version__
from texsense.io import load
from texsense.layout import Layout
from texsense.recording import Recording

__all__ = ["Layout", "Recording", "__version__", "load"]
