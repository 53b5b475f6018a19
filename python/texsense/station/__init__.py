"""The ward station: many mats over a real MQTT broker, one overview (docs/station.md).

- :mod:`texsense.station.broker`: a Mosquitto of the station's own on loopback;
- :mod:`texsense.station.ward`: the engine — one MQTT connection, a monitor per mat, stale and
  refused mats, malformed payloads counted per mat;
- :mod:`texsense.station.virtual`: simulated people on virtual seats publishing through the
  broker;
- :mod:`texsense.station.server`: the ward page, REST, the ward WebSocket, and every mat's
  dashboard.
"""
