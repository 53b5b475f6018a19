"""The chain of stages of a mat: its calibration, in one file (``texsense.chain``)."""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

from texsense.compensation.drift import DriftModel
from texsense.compensation.health import FailureDetector
from texsense.compensation.hysteresis import HysteresisModel
from texsense.compensation.stage import STAGES, Stage, Stream, time_steps
from texsense.compensation.stages.convert import Convert, Linear
from texsense.compensation.stages.spacer import Drift, Hysteresis
from texsense.data.layout import Layout, parse_orientation
from texsense.data.modelfile import Fields, content_hash, load, unpack, write
from texsense.data.recording import Recording
from texsense.exceptions import FormatError, NotFittedError, ParameterError

__all__ = ["STAGES", "StageChain", "load_chain", "load_stage", "stage_from_dict"]

S = TypeVar("S", bound=Stage)


def stage_from_dict(content: Any, source: str | Path = "<dict>") -> Stage:
    """Any stage from its content in a model file; every problem raises
    :class:`FormatError` naming the file and the field."""
    if not isinstance(content, dict):
        raise FormatError(source, "a stage must be a JSON object")
    name = content.get("stage")
    cls = STAGES.get(name) if isinstance(name, str) else None
    if cls is None:
        raise FormatError(source, f"unknown stage {name!r}; known: {', '.join(sorted(STAGES))}")
    return cls.from_dict(content, source)


class StageChain(Stream):
    """The fitted stages of a mat in order, each reading what the one before gives: the one
    calibration of texsense (docs/pipeline.md). A mat's chain is ``detect``, ``convert``,
    ``hysteresis`` and ``drift`` (the last optional; ``linear`` in place of convert and the
    spacer's stages for a mat without a spacer model); a repair stage is chosen when
    processing (:class:`texsense.compensation.pipeline.Pipeline`), not stored with the calibration.

    It follows the stage contract (:mod:`texsense.compensation.stage`): ``step(values, valid, t)``,
    ``run(recording)``, ``reset()``; ``Pipeline(chain, layout)`` runs the same kernels as
    one compiled pass and gives the same numbers.
    """

    def __init__(
        self, stages: Sequence[Stage], orientation: Mapping[str, str] | str | None = None
    ) -> None:
        stages = list(stages)
        if not stages:
            raise ParameterError("a chain needs at least one stage")
        for s in stages:
            s._check_fitted()
        flowing = stages[0].reads
        for s in stages:
            wants = s.reads[0]
            if wants and flowing[0] and wants != flowing[0]:
                names = [x.name for x in stages]
                raise ParameterError(
                    f"the {s.name} stage reads {wants}, the stage before gives {flowing[0]} "
                    f"(chain {names})"
                )
            flowing = (s.gives[0] or flowing[0], s.gives[1] or flowing[1])
        for before, s in zip([None, *stages], stages, strict=False):
            if isinstance(s, Drift) and s.needs_inputs and not isinstance(before, Hysteresis):
                raise ParameterError(
                    "a drift stage that relaxes the elastic response (QLV) must follow the "
                    f"hysteresis stage directly (chain {[x.name for x in stages]})"
                )
        self.stages = stages
        #: how the mat lies (what lies beyond each edge of its map), declared when it was
        #: calibrated (``texsense calibrate wizard``, the monitor's calibration panel); {}
        #: when not declared. Not part of :attr:`id`: it describes the mat, not the fit.
        self.orientation = parse_orientation(orientation)
        self._last_t: float | None = None

    def __getitem__(self, name: str) -> Stage:
        for s in self.stages:
            if s.name == name:
                return s
        raise KeyError(name)

    def get(self, name: str, default: Stage | None = None) -> Stage | None:
        """The stage named ``name``, or ``default``."""
        return next((s for s in self.stages if s.name == name), default)

    def find(self, kind: type[S]) -> S | None:
        """The (first) stage of class ``kind``, or None."""
        return next((s for s in self.stages if isinstance(s, kind)), None)

    def __contains__(self, name: object) -> bool:
        return any(s.name == name for s in self.stages)

    def __iter__(self) -> Iterator[Stage]:
        return iter(self.stages)

    @property
    def names(self) -> list[str]:
        """The stages' names in order."""
        return [s.name for s in self.stages]

    @property
    def reads(self) -> tuple[str, str]:
        """(quantity, unit) the chain reads."""
        return self.stages[0].reads

    @property
    def gives(self) -> tuple[str, str]:
        """(quantity, unit) the chain gives."""
        q, u = self.reads
        for s in self.stages:
            q, u = s.gives[0] or q, s.gives[1] or u
        return q, u

    @property
    def conversion(self) -> Convert | Linear | None:
        """The conversion stage (convert or linear), if any."""
        for s in self.stages:
            if isinstance(s, Convert | Linear):
                return s
        return None

    @property
    def n_elements(self) -> int | None:
        """Number of elements of the mat (None when no stage knows it)."""
        for s in self.stages:
            if isinstance(s, Convert | Linear):
                return s.n_elements
            layout = getattr(s, "layout", None)
            if isinstance(layout, Layout):
                return layout.n_elements
        return None

    @property
    def id(self) -> str:
        """Content hash of every stage's parameters and learned state (the first 16 hex
        digits of the file's sha256), written into the provenance of every output."""
        return content_hash({"stages": self.to_dict()["stages"]})[:16]

    def without(self, *names: str) -> StageChain:
        """The chain without the stages named (e.g. ``"drift"``)."""
        return StageChain([s for s in self.stages if s.name not in names], self.orientation)

    # ------------------------------------------------------------------ building
    @classmethod
    def fit_mat(
        cls,
        material: Mapping[str, np.ndarray],
        baseline: Recording,
        uniform: Recording,
        uniform_pressure_ncm2: float,
        thickness_mm: float,
        *,
        steps: Sequence[Any] | None = None,
        drift: Drift | None = None,
    ) -> StageChain:
        """The calibration of a mat: convert (zeroing, equilibration, eq. 2.1), hysteresis
        from the material record (eq. 4.15-4.22), drift from held steps (eq. 5.8) if given
        (or a fitted ``drift`` stage), and detection with the expected range of every
        element. A material record with ``held_out_compression_mm`` and
        ``held_out_pressure_ncm2`` (a record the hysteresis is not fitted on) gives the
        hysteresis model its held-out residuals, the scale of the bounds
        (:mod:`texsense.compensation.intervals`)."""
        convert = Convert(thickness_mm, uniform_pressure_ncm2).fit(material, baseline, uniform)
        hyst = Hysteresis().fit(material["compression_mm"], material["pressure_ncm2"])
        if "held_out_compression_mm" in material:  # a record not fitted on: the bounds' scale
            hyst.model_.hold_out(
                material["held_out_compression_mm"],
                material["held_out_pressure_ncm2"],
                "held-out record of the material",
            )
        lo, hi = convert.expected_range_pF()
        stages: list[Stage] = [FailureDetector(baseline.layout).fit(lo, hi), convert, hyst]
        if steps is not None and drift is not None:
            raise ParameterError("give held steps or a fitted drift stage, not both")
        if steps is not None:
            drift = Drift().fit(steps)
        if drift is not None:
            stages.append(drift)
        return cls(stages)

    # ------------------------------------------------------------------ the stream
    def _what(self) -> str:
        return "the chain"

    def reset(self) -> StageChain:
        """Every stage's stream forgotten."""
        self._last_t = None
        for s in self.stages:
            s.reset()
        return self

    def _arrays(
        self, values: npt.ArrayLike, valid: npt.ArrayLike | None, times: npt.ArrayLike
    ) -> tuple[np.ndarray, np.ndarray]:
        x = np.ascontiguousarray(values, dtype=np.float64)
        ok = np.ones(x.shape, bool) if valid is None else np.asarray(valid, dtype=bool)
        t = np.asarray(times, dtype=np.float64).reshape(-1)
        if x.ndim != 2 or ok.shape != x.shape or t.shape != (x.shape[0],):
            raise ParameterError(
                f"expected values (T, N), valid of the same shape and T times; got "
                f"{x.shape}, {ok.shape}, {t.shape}"
            )
        ok = np.ascontiguousarray(ok & np.isfinite(x))
        if x.shape[0] == 0:
            return x, ok
        dt = time_steps(t, self._last_t)
        stage_inputs = x
        for s in self.stages:
            s._check_fitted()
            if isinstance(s, Drift) and s.needs_inputs:  # QLV: the hysteresis stage's inputs
                x, ok = s.block_on(x, ok, dt, stage_inputs)
            else:
                stage_inputs = x
                x, ok = s._block(x, ok, dt)
            s._last_t = float(t[-1])
        self._last_t = float(t[-1])
        return x, ok

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict[str, Any]:
        """The content of the chain file: the stages in order (and the mat's orientation
        when declared)."""
        out: dict[str, Any] = {"stages": [s.to_dict() for s in self.stages]}
        if self.orientation:
            out["orientation"] = dict(self.orientation)
        return out

    def save(self, path: str | Path) -> Path:
        """Write the chain file (``texsense.chain``), atomically."""
        return write(path, "texsense.chain", self.to_dict())

    @classmethod
    def from_dict(cls, content: Any, source: str | Path = "<dict>") -> StageChain:
        """A chain from the content of its file (:meth:`to_dict`)."""
        stages = Fields(content, source).get("stages")
        if not isinstance(stages, list):
            raise FormatError(source, "field 'stages': expected a list")
        built = [stage_from_dict(s, source) for s in stages]
        try:
            return cls(built, Fields(content, source).get("orientation", None))
        except (ParameterError, NotFittedError) as e:
            raise FormatError(source, str(e)) from None

    def __repr__(self) -> str:
        return f"StageChain({self.names}, id {self.id})"


def _as_chain(fmt: str, content: dict[str, Any], source: str | Path) -> StageChain:
    """Any model file's content as a chain."""
    if fmt == "texsense.chain":
        return StageChain.from_dict(content, source)
    if fmt == "texsense.stage":
        return StageChain([stage_from_dict(content, source)])
    fields = Fields(content, source)
    if fmt == "texsense.hysteresis":
        return StageChain([Hysteresis.of(HysteresisModel.from_content(fields))])
    return StageChain([Drift.of(DriftModel.from_content(fields))])


def chain_from_dict(d: Any, source: str | Path = "<dict>") -> StageChain:
    """A chain from a model file's JSON (any format and version :func:`load_chain` reads)."""
    fmt, content = unpack(d, source)
    return _as_chain(fmt, content, source)


def load_chain(path: str | Path) -> StageChain:
    """Read a calibration: a chain file, or any model file as a chain of its stages (a stage,
    a hysteresis or drift model), of this version or an earlier one (:mod:`texsense.data.legacy`:
    the first round's calibration files, linear calibrations, hysteresis models with drift).
    Every problem is one :class:`FormatError` naming the file."""
    fmt, content = load(path)
    return _as_chain(fmt, content, path)


def load_stage(path: str | Path) -> Stage:
    """Read a stage file."""
    _, content = load(path, ("texsense.stage",))
    return stage_from_dict(content, path)
