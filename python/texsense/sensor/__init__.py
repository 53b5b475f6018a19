"""Sensor physics: electrode capacitance (eq. 2.1, §3.4) and the design rules (§2.3.2, §7.2)."""

from texsense.sensor.electrode import Electrode, permittivity

__all__ = ["Electrode", "permittivity"]
