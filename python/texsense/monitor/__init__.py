"""The live monitor (docs/monitor.md): sources, real-time processing, crash-safe recording,
exposure alerts, the event store and the web dashboard."""

from texsense.monitor.alerts import Alert, Event, ExposureTracker
from texsense.monitor.live import Monitor, Recorder
from texsense.monitor.protocol import Frame, ProtocolError
from texsense.monitor.sources import (
    IIOSource,
    MQTTSource,
    ReplaySource,
    SerialSource,
    Source,
    VirtualSeatSource,
)
from texsense.monitor.store import EventStore

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
    "VirtualSeatSource",
]
