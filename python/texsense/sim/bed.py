"""Virtual people on a virtual bed mat (issue 17, docs/bed.md).

The mat is a common commercial size: 64 x 32 textile elements at 2.54 cm (162.6 x 81.3 cm,
the size of the Vista FSA SoftFlex 2048 mat of the PhysioNet PMD data), head end at row 0,
read by 32 AD7745-class converters in parallel (a frame about every second).

A lying body is a sum of anisotropic Gaussian pressure patches in body coordinates: soft
segments (head, back, buttocks, thighs, calves, arms: wide, low) and bony prominences
(occiput, scapulae, sacrum, heels lying on the back; shoulder, trochanter, knee, ankle on
the side; iliac crests, knees, toes lying prone; ischia sitting up: narrow, high). The
body's total force is its weight; the peaks come out as interface pressures on a standard
mattress do: about 60-90 mmHg at the sacrum and the heels lying on the back, 80-110 mmHg at
the trochanter on the side. This is a shape model for ground truth, built from anatomy and
published interface-pressure ranges; it has nothing of the spacer or of the compensation.

Positions (:data:`POSITIONS`, each with its *side*, :data:`SIDES`): supine and three supine
variants (arms out, knees up, legs apart), prone (head turned left or right, arms up),
lateral left and right (straight, foetal, and tilted 30° on a pillow) and sitting up in bed.
People (:class:`Sleeper`) differ in height (155-190 cm: every distance scales with it),
weight (50-110 kg), tissue softness (the spread of every patch ±10 %), build (each patch's
share ±20 %) and where and how straight they lie (±5 cm across, ±8° rotation, the top
of the head from 8 cm beyond the mat's head edge, on the pillow, to 2 cm onto the mat);
within a person each take moves ±1.5 cm and ±2°. Whatever falls beyond the mat's edges is
lost, as on a real mat (tall people lose their heels).

:func:`bed_session` puts one person through a night: positions held for minutes, turns of
a few seconds between them (labelled ``transition``), sitting up, getting out of bed and
back. Its truth carries, per frame, the position, the side and where each bony prominence
lies (:data:`PROMINENCES`), the reference for the at-risk regions found from the map
(:mod:`texsense.apps.bed`).

Examples
--------
>>> from texsense.sim.bed import Sleeper, bed_layout, lying_pressure
>>> lay = bed_layout()
>>> p = lying_pressure(lay, "supine", Sleeper())
>>> p.shape, round(float(p.sum()) * 2.54**2)  # elements, N (of 736: the rest is off the mat)
((2048,), 733)
>>> [round(float(lying_pressure(lay, k).max()) * 75.006) for k in ("supine", "left")]  # mmHg
[68, 120]
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from texsense.data.layout import Layout
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError
from texsense.sensor.readout import CDC
from texsense.sim.mat import VirtualMat
from texsense.sim.seated import SEAT_FAILURES

__all__ = [
    "BED_COLS",
    "BED_CONVERTERS",
    "BED_PITCH_CM",
    "BED_ROWS",
    "POSITIONS",
    "PROMINENCES",
    "SIDES",
    "BedFrame",
    "BedSession",
    "Placement",
    "Sleeper",
    "bed_layout",
    "bed_mat",
    "bed_session",
    "every_position",
    "lying_pressure",
    "night_frames",
    "night_plan",
    "prominences",
]

BED_ROWS, BED_COLS, BED_PITCH_CM = 64, 32, 2.54
#: Converters reading the bed mat in parallel (64 elements each: a frame about every 1.06 s).
BED_CONVERTERS = 32
#: Height of the model body, cm (all positions are drawn for it and scaled).
_MODEL_HEIGHT_CM = 175.0
#: Where the body's hips are (cm from the top of the head): the pivot of a rotation.
_HIP_U = 85.0

#: The sides a person can lie (or sit) on: what the turning schedule counts.
SIDES = ("supine", "prone", "left", "right", "sitting")

# A patch: (name or "", u cm from the top of the head, v cm across (+: towards the mat's
# last column), σ along, σ across, peak N/cm² before scaling to the body weight). Named
# patches are bony prominences: their centres are the truth of the at-risk regions.
_Patch = tuple[str, float, float, float, float, float]

_ARMS_ALONG: list[_Patch] = [
    ("", 62, -24, 17, 3, 0.22),
    ("", 62, 24, 17, 3, 0.22),
    ("", 66, -25, 2.5, 2.5, 0.5),
    ("", 66, 25, 2.5, 2.5, 0.5),  # elbows
]
_SUPINE_HEAD_TRUNK: list[_Patch] = [
    ("occiput", 10, 0, 3.5, 3.5, 1.1),
    ("", 11, 0, 6, 5, 0.25),
    ("scapula-l", 32, -9, 4.5, 4, 0.85),
    ("scapula-r", 32, 9, 4.5, 4, 0.85),
    ("", 40, 0, 13, 13, 0.3),
    ("", 64, 0, 8, 10, 0.12),  # lumbar curve: little contact
]
_SUPINE_PELVIS: list[_Patch] = [
    ("sacrum", 80, 0, 4.5, 4.5, 2.3),
    ("", 86, -9, 7, 7, 0.8),
    ("", 86, 9, 7, 7, 0.8),  # buttocks
]
_SUPINE_LEGS: list[_Patch] = [
    ("", 108, -9, 12, 5, 0.32),
    ("", 108, 9, 12, 5, 0.32),  # thighs
    ("", 134, -9, 9, 3.5, 0.42),
    ("", 134, 9, 9, 3.5, 0.42),  # calves
    ("heel-l", 158, -9, 2.5, 2.5, 1.9),
    ("heel-r", 158, 9, 2.5, 2.5, 1.9),
]
_LEFT: list[_Patch] = [
    ("", 11, -1, 5, 4, 0.6),  # head on its side
    ("shoulder", 31, -3, 4, 4, 1.4),
    ("", 50, -2, 12, 5, 0.32),  # ribs
    ("", 50, 9, 11, 3, 0.18),  # the upper arm's forearm in front
    ("trochanter", 84, -3, 4.5, 4.5, 1.8),
    ("", 86, -3, 9, 6, 0.38),  # hip
    ("", 108, -2, 12, 4, 0.32),  # thigh
    ("knee", 127, -1, 3, 3, 1.1),
    ("", 143, -1, 8, 3, 0.28),  # calf
    ("ankle", 160, -1, 2.5, 2.5, 1.1),
]
_LEFT_FOETAL: list[_Patch] = [
    ("", 13, 3, 5, 4, 0.6),
    ("shoulder", 31, -3, 4, 4, 1.4),
    ("", 50, 0, 12, 5, 0.32),
    ("", 46, 11, 9, 3, 0.2),
    ("trochanter", 84, -3, 4.5, 4.5, 1.8),
    ("", 88, -1, 8, 6, 0.38),
    ("", 100, 8, 9, 5, 0.32),  # thigh drawn up
    ("knee", 108, 17, 3, 3, 1.1),
    ("", 122, 10, 8, 3, 0.28),
    ("ankle", 136, 2, 2.5, 2.5, 1.1),
]
_PRONE: list[_Patch] = [
    ("", 40, 0, 11, 12, 0.5),  # chest
    ("", 64, 0, 8, 10, 0.25),  # belly
    ("iliac-crest-l", 80, -10, 3.5, 3.5, 1.2),
    ("iliac-crest-r", 80, 10, 3.5, 3.5, 1.2),
    ("", 88, 0, 8, 11, 0.28),
    ("", 108, -9, 12, 5, 0.38),
    ("", 108, 9, 12, 5, 0.38),  # thighs
    ("knee-l", 127, -9, 3, 3, 1.3),
    ("knee-r", 127, 9, 3, 3, 1.3),
    ("", 143, -9, 9, 3, 0.28),
    ("", 143, 9, 9, 3, 0.28),  # shins
    ("", 171, -10, 2.5, 3, 0.7),
    ("", 171, 10, 2.5, 3, 0.7),  # toes
]
_SITTING: list[_Patch] = [
    ("ischium-l", 84, -6.5, 3, 3, 2.5),
    ("ischium-r", 84, 6.5, 3, 3, 2.5),
    ("", 77, 0, 3.5, 3, 0.7),  # sacrum and coccyx, behind the ischia
    ("", 88, -8, 6, 7, 0.8),
    ("", 88, 8, 6, 7, 0.8),
    ("", 108, -9, 12, 5, 0.5),
    ("", 108, 9, 12, 5, 0.5),
    ("", 134, -9, 9, 3.5, 0.45),
    ("", 134, 9, 9, 3.5, 0.45),
    ("heel-l", 158, -9, 2.5, 2.5, 1.9),
    ("heel-r", 158, 9, 2.5, 2.5, 1.9),
]


def _swap_side(name: str) -> str:
    """``scapula-l`` <-> ``scapula-r``; other names stay."""
    ends = {"-l": "-r", "-r": "-l"}
    return name[:-2] + ends[name[-2:]] if name[-2:] in ends else name


def _mirrored(patches: list[_Patch]) -> list[_Patch]:
    """The mirror image across the mat's centre line."""
    return [(_swap_side(n), u, -v, su, sv, pk) for n, u, v, su, sv, pk in patches]


def _tilted(lateral: list[_Patch]) -> list[_Patch]:
    """Lying 30° towards the side of ``lateral`` on a pillow behind the back: the lower half
    of the back and the lower buttock take the load, the sacrum is half relieved."""
    supine = _SUPINE_HEAD_TRUNK + _SUPINE_PELVIS + _SUPINE_LEGS + _ARMS_ALONG
    down = -1.0 if lateral is _LEFT else 1.0
    out: list[_Patch] = []
    for _, u, v, su, sv, pk in supine:  # no prominence takes a clear load: no names
        w = 1.5 if v * down > 0 else (0.35 if v * down < 0 else 0.6)
        out.append(("", u, v + 2 * down, su, sv, pk * w))
    out.append(("", 84, 13 * down, 5, 4, 0.9))  # the side of the pelvis, towards the trochanter
    return out


def _apart(patch: _Patch) -> _Patch:
    """A leg patch with the legs spread: 12 % of its distance below the hips outwards."""
    n, u, v, su, sv, pk = patch
    return (n, u, v + float(np.sign(v)) * (u - 95) * 0.12, su, sv, pk)


_SUPINE = _SUPINE_HEAD_TRUNK + _SUPINE_PELVIS + _SUPINE_LEGS + _ARMS_ALONG
_POSITIONS: dict[str, tuple[str, list[_Patch]]] = {
    "supine": ("supine", _SUPINE),
    "supine, arms out": (
        "supine",
        _SUPINE_HEAD_TRUNK
        + _SUPINE_PELVIS
        + _SUPINE_LEGS
        + [("", 38, -34, 3, 13, 0.22), ("", 38, 34, 3, 13, 0.22)],
    ),
    "supine, knees up": (
        "supine",
        _SUPINE_HEAD_TRUNK
        + [(n, u, v, su, sv, pk * 1.25) for n, u, v, su, sv, pk in _SUPINE_PELVIS]
        + [("", 100, -9, 8, 5, 0.25), ("", 100, 9, 8, 5, 0.25)]
        + [("", 128, -10, 6, 3.5, 0.9), ("", 128, 10, 6, 3.5, 0.9)]  # feet flat
        + [("heel-l", 133, -10, 2.5, 2.5, 1.4), ("heel-r", 133, 10, 2.5, 2.5, 1.4)]
        + _ARMS_ALONG,
    ),
    "supine, legs apart": (
        "supine",
        _SUPINE_HEAD_TRUNK + _SUPINE_PELVIS + [_apart(p) for p in _SUPINE_LEGS] + _ARMS_ALONG,
    ),
    "prone, head left": ("prone", [("", 12, -4, 5, 4, 0.6), *_PRONE, *_ARMS_ALONG]),
    "prone, head right": ("prone", [("", 12, 4, 5, 4, 0.6), *_PRONE, *_ARMS_ALONG]),
    "prone, arms up": (
        "prone",
        [("", 12, 4, 5, 4, 0.6), *_PRONE, ("", 14, -22, 9, 3, 0.3), ("", 14, 22, 9, 3, 0.3)],
    ),
    "left": ("left", _LEFT),
    "left, foetal": ("left", _LEFT_FOETAL),
    "left, 30° tilt": ("left", _tilted(_LEFT)),
    "right": ("right", _mirrored(_LEFT)),
    "right, foetal": ("right", _mirrored(_LEFT_FOETAL)),
    "right, 30° tilt": ("right", _mirrored(_tilted(_LEFT))),
    "sitting up": ("sitting", _SITTING),
}
#: Every position a virtual person takes, and its side.
POSITIONS: dict[str, str] = {k: side for k, (side, _) in _POSITIONS.items()}
#: The bony prominences the simulation knows the place of, per side.
PROMINENCES: dict[str, tuple[str, ...]] = {
    side: tuple(sorted({n for k, (s, ps) in _POSITIONS.items() if s == side for n, *_ in ps if n}))
    for side in SIDES
}


def bed_layout() -> Layout:
    """The 64 x 32 bed mat at 2.54 cm, head end at row 0; the first column is the side the
    virtual body's left (``scapula-l``, ``heel-l``) lies on when it lies on its back."""
    lay = Layout.grid(BED_ROWS, BED_COLS, pitch_cm=BED_PITCH_CM, element_size_cm=2.2)
    return lay.with_orientation("bed")


def bed_mat(seed: int = 7, failures: bool = True) -> VirtualMat:
    """The virtual bed mat: :func:`bed_layout`, textile spacer, :data:`BED_CONVERTERS`
    converters; with ``failures``, elements fail at the rates the thesis measured on its
    textile seat (§6.5.2.5, :data:`texsense.sim.seated.SEAT_FAILURES`: the only measured
    rates for this sensor). The same ``seed`` is the same physical mat."""
    return VirtualMat(
        bed_layout(),
        "textile-3mm",
        converters=BED_CONVERTERS,
        seed=seed,
        failures=SEAT_FAILURES if failures else None,
    )


@dataclass(frozen=True)
class Sleeper:
    """One virtual person: height (cm), weight (kg), tissue softness (spread of every patch,
    1 = the model), build (a share factor per patch, drawn from ``build_seed``) and the
    person's usual place on the mat (``across_cm`` off the centre line, ``head_cm`` from the
    head edge to the top of the head, ``angle_deg``)."""

    height_cm: float = _MODEL_HEIGHT_CM
    weight_kg: float = 75.0
    softness: float = 1.0
    build_seed: int | None = None
    across_cm: float = 0.0
    head_cm: float = -3.0
    angle_deg: float = 0.0
    name: str = "model"

    @classmethod
    def random(cls, index: int, seed: int = 0) -> Sleeper:
        """Person ``index`` of a population drawn with ``seed``."""
        rng = np.random.default_rng([seed, index, 17])
        return cls(
            height_cm=float(rng.uniform(155, 190)),
            weight_kg=float(rng.uniform(50, 110)),
            softness=float(rng.uniform(0.9, 1.1)),
            build_seed=int(rng.integers(2**31)),
            across_cm=float(rng.uniform(-5, 5)),
            head_cm=float(rng.uniform(-8, 2)),
            angle_deg=float(rng.uniform(-8, 8)),
            name=f"P{index + 1}",
        )


@dataclass(frozen=True)
class Placement:
    """How one take of a position differs from the person's usual place: cm along (towards
    the feet) and across, degrees of rotation."""

    along_cm: float = 0.0
    across_cm: float = 0.0
    angle_deg: float = 0.0

    @classmethod
    def random(cls, rng: np.random.Generator) -> Placement:
        """A take: ±1.5 cm, ±2° (1 σ)."""
        a, b, c = rng.normal(0.0, (1.5, 1.5, 2.0))
        return cls(float(a), float(b), float(c))


def _patches(position: str, sleeper: Sleeper, place: Placement) -> np.ndarray:
    """The position's patches (K, 6: x cm, y cm, σ along, σ across, peak before scaling,
    rotation) in mat coordinates."""
    if position not in _POSITIONS:
        raise ParameterError(f"unknown position {position!r}; known: {'; '.join(POSITIONS)}")
    patches = _POSITIONS[position][1]
    s = sleeper.height_cm / _MODEL_HEIGHT_CM
    a = np.array([[u, v, su, sv, pk] for _, u, v, su, sv, pk in patches], dtype=np.float64)
    if sleeper.build_seed is not None:
        build = np.random.default_rng([sleeper.build_seed, len(patches)])
        a[:, 4] *= build.uniform(0.8, 1.2, len(patches))
    u, v = (a[:, 0] - _HIP_U) * s, a[:, 1] * s  # about the hips
    th = np.deg2rad(sleeper.angle_deg + place.angle_deg)
    x_mid = BED_COLS * BED_PITCH_CM / 2.0
    hip_y = sleeper.head_cm + place.along_cm + _HIP_U * s
    x = x_mid + sleeper.across_cm + place.across_cm + v * np.cos(th) + u * np.sin(th)
    y = hip_y - v * np.sin(th) + u * np.cos(th)
    spread = s * sleeper.softness
    return np.column_stack([x, y, a[:, 2] * spread, a[:, 3] * spread, a[:, 4], np.full(len(a), th)])


def lying_pressure(
    layout: Layout,
    position: str,
    sleeper: Sleeper | None = None,
    place: Placement | None = None,
) -> np.ndarray:
    """True pressure (N/cm², one value per element of ``layout``, a grid with the head end at
    row 0) of ``sleeper`` (default: the 175 cm, 75 kg model) in ``position`` (any of
    :data:`POSITIONS`). The patches give the shape; their total force is the body weight, and
    what falls beyond the mat is lost."""
    sleeper = sleeper or Sleeper()
    k = _patches(position, sleeper, place or Placement())
    xy = np.asarray(layout.xy_cm)
    p = np.zeros(layout.n_elements)
    total = 0.0
    for x, y, su, sv, pk, th in k:
        dx, dy = xy[:, 0] - x, xy[:, 1] - y
        along = dx * np.sin(th) + dy * np.cos(th)
        across = dx * np.cos(th) - dy * np.sin(th)
        p += pk * np.exp(-0.5 * ((along / su) ** 2 + (across / sv) ** 2))
        total += pk * 2.0 * np.pi * su * sv  # the patch's integral over the plane
    return p * (sleeper.weight_kg * 9.81 / total)


def prominences(
    position: str, sleeper: Sleeper | None = None, place: Placement | None = None
) -> dict[str, tuple[float, float]]:
    """Where the bony prominences of ``position`` lie: name -> (x, y) cm on the mat, for
    those on the mat."""
    sleeper = sleeper or Sleeper()
    k = _patches(position, sleeper, place or Placement())
    names = [n for n, *_ in _POSITIONS[position][1]]
    w, h = BED_COLS * BED_PITCH_CM, BED_ROWS * BED_PITCH_CM
    return {
        n: (float(x), float(y))
        for n, (x, y) in zip(names, k[:, :2], strict=True)
        if n and 0 <= x <= w and 0 <= y <= h
    }


@dataclass
class BedSession:
    """What :func:`bed_session` returns: the true pressure (labels ``position``, ``side`` —
    ``"out"`` when nobody is there, ``"transition"`` while turning —, ``hold`` (a position
    held: neither turning nor out of bed), ``subject``), the prominences per frame and, with a
    mat, the capacitance it read."""

    truth: Recording
    prominences: list[dict[str, tuple[float, float]]]  # per frame: name -> (x, y) cm
    capacitance: Recording | None = None
    sleeper: Sleeper = field(default_factory=Sleeper)


def night_plan(
    rng: np.random.Generator,
    n_positions: int,
    hold_s: float,
    *,
    sit_every: int = 5,
    out_every: int = 8,
    away_s: float = 120.0,
    spread: tuple[float, float] = (0.7, 1.3),
) -> list[tuple[str, float]]:
    """A plausible sequence of (position, seconds): lying positions held ``hold_s`` times a
    factor drawn from ``spread``, on another side than the one before, sitting up (half as
    long) after every ``sit_every`` positions and getting out of bed (``"out"``) after
    every ``out_every`` (0: never)."""
    lying = [k for k, side in POSITIONS.items() if side != "sitting"]
    plan: list[tuple[str, float]] = []
    last = ""
    for i in range(n_positions):
        choices = [k for k in lying if POSITIONS[k] != POSITIONS.get(last, "")]
        last = str(rng.choice(choices))
        plan.append((last, hold_s * float(rng.uniform(*spread))))
        if sit_every and (i + 1) % sit_every == 0:
            plan.append(("sitting up", hold_s * 0.5 * float(rng.uniform(*spread))))
        if out_every and (i + 1) % out_every == 0:
            plan.append(("out", away_s))
    return plan


@dataclass(frozen=True)
class BedFrame:
    """One frame of a simulated night: time, true pressure, the position (``"out"``: an
    empty bed, ``"transition"``: turning), its side, the prominences (name -> x, y cm)."""

    t: float
    pressure: np.ndarray
    position: str
    side: str
    prominences: dict[str, tuple[float, float]]


def night_frames(
    sleeper: Sleeper,
    plan: Iterable[tuple[str, float]],
    rng: np.random.Generator,
    *,
    frame_s: float,
    turn_s: float = 6.0,
    t0: float = 0.0,
) -> Iterator[BedFrame]:
    """The frames of ``plan`` (position or ``"out"``, seconds), lazily: each position held at
    a new :class:`Placement`, breathing (±2 % at 0.25 Hz), and for the first ``turn_s`` of
    every position the map blending from the previous one (labelled ``transition``)."""
    lay = bed_layout()
    n = lay.n_elements
    previous: np.ndarray | None = None
    t = t0
    for position, seconds in plan:
        if position != "out" and position not in POSITIONS:
            raise ParameterError(f"unknown position {position!r} in the plan")
        if seconds <= 0:
            raise ParameterError(f"every position must last > 0 s, got {seconds} for {position}")
        place = Placement.random(rng)
        if position == "out":
            target, marks = np.zeros(n), {}
        else:
            target = lying_pressure(lay, position, sleeper, place)
            marks = prominences(position, sleeper, place)
        start, end = t, t + seconds
        while t < end:
            if previous is not None and t - start < turn_s:
                w = (t - start) / turn_s
                yield BedFrame(t, (1 - w) * previous + w * target, "transition", "transition", {})
            else:
                breathe = 1.0 + 0.02 * np.sin(2 * np.pi * t / 4.0)
                side = POSITIONS.get(position, "out")
                yield BedFrame(t, target * breathe, position, side, marks)
            t += frame_s
        previous = target


def bed_session(
    sleeper: Sleeper,
    plan: list[tuple[str, float]] | None = None,
    *,
    seed: int = 0,
    turn_s: float = 6.0,
    mat: VirtualMat | None = None,
    frame_s: float | None = None,
    t0: float = 0.0,
) -> BedSession:
    """One person through ``plan`` (default: 10 positions of 5 min each, see
    :func:`night_plan`), a frame every ``frame_s`` (default the bed mat's frame time), turning
    for ``turn_s`` seconds between positions (:func:`night_frames`). With ``mat`` (e.g.
    :func:`bed_mat`) the session is also read by the textile sensor."""
    rng = np.random.default_rng([seed, 91])
    plan = plan if plan is not None else night_plan(rng, 10, 300.0)
    lay = bed_layout()
    if frame_s is None:
        frame_s = CDC().frame_time_s(lay.n_elements, BED_CONVERTERS)
    frames = list(night_frames(sleeper, plan, rng, frame_s=frame_s, turn_s=turn_s, t0=t0))
    if not frames:
        raise ParameterError("the plan holds no frame")
    labels = {
        "position": np.array([f.position for f in frames]),
        "side": np.array([f.side for f in frames]),
        "hold": np.array([f.side not in ("out", "transition") for f in frames]),
        "subject": np.full(len(frames), sleeper.name),
    }
    truth = Recording(
        np.vstack([f.pressure for f in frames]),
        np.array([f.t for f in frames]),
        lay,
        "pressure",
        "N/cm2",
        labels=labels,
    )
    capacitance = None
    if mat is not None:
        capacitance = mat.scan(truth.times, truth.frames).capacitance
        capacitance.labels.update(labels)
    return BedSession(truth, [f.prominences for f in frames], capacitance, sleeper)


def every_position(
    index: int, seed: int = 0, hold_s: float = 30.0, session_seed: int | None = None
) -> BedSession:
    """Person ``index`` of the population ``seed`` (:meth:`Sleeper.random`) takes every
    position once in a random order, each held ``hold_s``, on a fresh :func:`bed_mat` — the
    labelled data of the side model and of the bed benchmarks. ``session_seed`` (default
    ``index``) draws the takes."""
    rng = np.random.default_rng([seed, index])
    plan = [(str(p), hold_s) for p in rng.permutation(list(POSITIONS))]
    return bed_session(
        Sleeper.random(index, seed=seed),
        plan,
        seed=index if session_seed is None else session_seed,
        mat=bed_mat(),
        turn_s=min(6.0, hold_s / 3),
    )
