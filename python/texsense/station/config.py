"""One mat of a ward as the station is told of it (a ward file's ``[[mat]]``, a virtual
mat): :class:`MatConfig`. Kept apart from the station's engine so that what builds the
configurations (the virtual mats' own process included) need not load the engine."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from texsense.data.layout import Layout

if TYPE_CHECKING:
    from texsense.apps.posture.model import PostureModel
    from texsense.compensation.stages import StageChain

__all__ = ["MatConfig"]


@dataclass
class MatConfig:
    """One mat of the ward: its id (the topic segment before ``/frames``), layout, calibration
    (a stage chain or mat calibration; None for a mat that sends pressure), where its
    frames come from (``mqtt``, or a local source built by the command line) and, for a bed,
    its side model and turning schedule."""

    id: str
    layout: Layout
    calibration: StageChain | None = None
    quantity: str = "capacitance"
    source: str = "mqtt"
    reposition_min: float = 20.0
    extra: dict[str, Any] = field(default_factory=dict)
    #: A bed mat: the turning schedule on the side ``posture_model`` reports, and at-risk
    #: regions (:class:`texsense.apps.bed.BedWatch`); the model's labels must be sides.
    bed: bool = False
    posture_model: PostureModel | None = None
    turn_every_min: float = 120.0
    #: the settings its ward file's entry sets itself (``reposition_min``, ``turn_every_min``):
    #: the command line's defaults for them do not reach this mat
    own: frozenset[str] = frozenset()
    #: source seconds per wall second of its frames when known (a virtual mat's ``--speed``):
    #: the mat's clock starts from it (:class:`~texsense.monitor.clock.FrameClock`)
    rate: float = 1.0
