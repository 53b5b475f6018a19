"""How a mat lies: what lies beyond each edge of its map as drawn (row 0 at the top, column 0
on the left) — the orientation a :class:`~texsense.data.layout.Layout` carries, the presets
of a bed, a seat and a foot sensor, a preset turned toward an edge, and what people and
files give (docs/monitor.md, "How the mat lies").

>>> parse_orientation("bed:bottom")["top"]
'foot'
"""

from __future__ import annotations

from collections.abc import Mapping

from texsense.exceptions import ParameterError

__all__ = ["EDGES", "ORIENTATIONS", "orientation_toward", "parse_orientation"]

#: The edges of a map as drawn: ``top`` is row 0 (small y), ``left`` is column 0 (small x).
EDGES = ("top", "bottom", "left", "right")

#: Orientation presets. ``left`` / ``right`` are the body's own left and right: the patient's
#: lying on the back on a bed (head at the top), the sitter's on a seat (front edge at the top).
#: A foot sensor declares toes and heel only (its sides depend on which foot it is).
ORIENTATIONS: dict[str, dict[str, str]] = {
    "bed": {"top": "head", "bottom": "foot", "left": "left", "right": "right"},
    "seat": {"top": "front", "bottom": "back", "left": "left", "right": "right"},
    "foot": {"top": "toes", "bottom": "heel"},
}


#: The edges in clockwise order (a mat turned on the bed turns its labels round this ring).
_RING = ("top", "right", "bottom", "left")


def orientation_toward(kind: str, edge: str) -> dict[str, str]:
    """The orientation of a mat of ``kind`` (a preset of :data:`ORIENTATIONS`: ``bed``,
    ``seat``, ``foot``) lying with its head, front or toes at ``edge`` of the map as drawn
    (row 0 at the top): the preset turned round, as the mat is on the bed (turned, not
    turned over: the person's left stays their left).

    >>> orientation_toward("bed", "bottom")
    {'bottom': 'head', 'top': 'foot', 'right': 'left', 'left': 'right'}
    """
    if kind not in ORIENTATIONS:
        raise ParameterError(
            f"orientation: unknown kind {kind!r}; known: {', '.join(ORIENTATIONS)}"
        )
    if edge not in _RING:
        raise ParameterError(f"orientation: unknown edge {edge!r}; edges: {', '.join(EDGES)}")
    turn = _RING.index(edge)
    return {_RING[(_RING.index(e) + turn) % 4]: v for e, v in ORIENTATIONS[kind].items()}


def parse_orientation(value: Mapping[str, str] | str | None) -> dict[str, str]:
    """An orientation from what a person or a file gives: a preset name (``bed``), a preset
    turned toward an edge (``bed:bottom``: the head at the bottom, see
    :func:`orientation_toward`), ``EDGE=LABEL,...`` (``top=head,bottom=foot``), a mapping
    edge -> label, or ``none`` / None / empty (no orientation); :class:`ParameterError`
    naming what is wrong otherwise.

    >>> parse_orientation("seat")["top"], parse_orientation("none")
    ('front', {})
    """
    if isinstance(value, str):
        text = value.strip()
        if text.lower() in ("", "none", "unknown"):
            return {}
        if "=" in text:
            pairs = [p.split("=", 1) for p in text.split(",") if p.strip()]
            if any(len(p) != 2 for p in pairs):
                raise ParameterError(f"orientation: expected EDGE=LABEL,..., got {value!r}")
            return _orientation({k.strip(): v.strip() for k, v in pairs})
        if ":" in text:
            kind, edge = (x.strip() for x in text.split(":", 1))
            return orientation_toward(kind, edge)
    return _orientation(value)


def _orientation(value: Mapping[str, str] | str | None) -> dict[str, str]:
    """Check an orientation (a preset name or edge -> label) and return it as a dict."""
    if value is None:
        return {}
    if isinstance(value, str):
        if value not in ORIENTATIONS:
            raise ParameterError(
                f"orientation: unknown preset {value!r}; known: {', '.join(ORIENTATIONS)}"
            )
        return dict(ORIENTATIONS[value])
    if not isinstance(value, Mapping):
        raise ParameterError("orientation: expected a preset name or a mapping edge -> label")
    out: dict[str, str] = {}
    for edge, label in value.items():
        if edge not in EDGES:
            raise ParameterError(f"orientation: unknown edge {edge!r}; edges: {', '.join(EDGES)}")
        if not isinstance(label, str) or not label.strip() or len(label) > 40:
            raise ParameterError(f"orientation: the {edge} label must be a short text")
        out[edge] = label.strip()
    return out
