"""The live monitor (docs/monitor.md): sources, real-time processing, crash-safe recording,
exposure alerts, the event store and the web dashboard."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from texsense.apps.alerts import Alert, Event, ExposureTracker
    from texsense.data.protocol import Frame, ProtocolError
    from texsense.monitor.devices import IIOSource, MQTTSource, SerialSource
    from texsense.monitor.live import Monitor, Recorder
    from texsense.monitor.sources import ReplaySource, Source
    from texsense.monitor.store import EventStore
    from texsense.monitor.virtual import VirtualBedSource, VirtualSeatSource

#: The package's names and the modules that define them, imported when first used (so that
#: importing one of them does not load the monitor's server and sources).
_LAZY = {
    **dict.fromkeys(("Alert", "Event", "ExposureTracker"), "texsense.apps.alerts"),
    **dict.fromkeys(("Monitor", "Recorder"), "texsense.monitor.live"),
    **dict.fromkeys(("Frame", "ProtocolError"), "texsense.data.protocol"),
    **dict.fromkeys(("ReplaySource", "Source"), "texsense.monitor.sources"),
    **dict.fromkeys(("IIOSource", "MQTTSource", "SerialSource"), "texsense.monitor.devices"),
    **dict.fromkeys(("VirtualBedSource", "VirtualSeatSource"), "texsense.monitor.virtual"),
    "EventStore": "texsense.monitor.store",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'texsense.monitor' has no attribute {name!r}")


__all__ = [
    "Alert",
    "Event",
    "EventStore",
    "ExposureTracker",
    "Frame",
    "IIOSource",
    "MQTTSource",
    "Monitor",
    "ProtocolError",
    "Recorder",
    "ReplaySource",
    "SerialSource",
    "Source",
    "VirtualBedSource",
    "VirtualSeatSource",
]
