"""Calibrating a new mat from the monitor's page (docs/monitor.md, "Calibrate from the page"):
the steps of ``texsense calibrate wizard`` on the live stream of a running monitor.

1. **zero**: nothing on the mat; ``N`` frames of the live stream are kept (zeroing, §3.4.1);
2. **uniform**: a uniform known load ``P`` on every element; ``N`` frames (equilibration:
   eq. 2.1's offset and gain per element, §6.1);
3. **material**: a spacer preset (default: the spacer the device announced); the two
   recordings are checked and the chain is fitted by
   :class:`~texsense.calibration.session.CalibrationSession` (refusals carry every reason,
   warnings are kept);
4. **check**: another known load ``P2``; ``N`` frames read through the new calibration, per
   element (:class:`~texsense.calibration.session.CheckReport`);
5. **save**: the chain is written to a new file in the monitor's recordings folder (never
   over an existing one), the step recordings as HDF5 beside it, and the running monitor
   switches to calibrated pressure (:meth:`Monitor.use_calibration`).

Besides the steps, **how the mat lies** (:meth:`PageCalibration.set_orientation`): a bed, a
seat or a foot sensor with its head, front or toes at an edge of the map — chosen, or found
where a hand presses on the mat after step 1. It applies to the live map at once and is
written into the calibration (the monitor names left and right only when it is known).

:class:`PageCalibration` holds the steps; it taps the monitor's frames (after the mat's clock,
so a glitching time stamp never enters a step recording). Steps must come in order; doing a
step again discards the steps after it. The routes are :mod:`texsense.monitor.routes.calibration`.
"""

from __future__ import annotations

import asyncio
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from texsense.calibration.checks import edge_of_press, parse_pressure, typical_reading
from texsense.calibration.session import CHECK_TOLERANCE, CalibrationSession, CheckReport
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import Convert, StageChain
from texsense.data.files import make_folder, unused_name
from texsense.data.layout import orientation_toward
from texsense.data.protocol import Frame
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError
from texsense.monitor.live import Monitor
from texsense.monitor.sources import blocking
from texsense.sensor.materials import PRESETS as SPACER_PRESETS

__all__ = ["DEFAULT_FRAMES", "MAX_FRAMES", "STEPS", "PageCalibration", "StepError"]

log = logging.getLogger("texsense.monitor")

#: The steps, in their order.
STEPS = ("zero", "uniform", "material", "check", "save")
#: The steps that record frames of the live stream.
RECORDED = ("zero", "uniform", "check")
#: Frames a step records unless told otherwise.
DEFAULT_FRAMES = 10
#: Most frames one step may record.
MAX_FRAMES = 2000
#: The check names this many elements of the largest error.
WORST = 5
#: The words of each step, for messages.
STEP_TEXT = {
    "zero": "the empty mat (step 1)",
    "uniform": "the uniform load (step 2)",
    "material": "the material and fit (step 3)",
    "check": "the check load (step 4)",
    "save": "save and use (step 5)",
}


class StepError(ParameterError):
    """A step asked for out of order, or while another one runs (HTTP 409)."""


class _Capture:
    """Frames of the live stream being kept for one step."""

    def __init__(self, step: str, frames: int, pressure_ncm2: float | None) -> None:
        self.step, self.target, self.pressure_ncm2 = step, frames, pressure_ncm2
        self.values: list[np.ndarray] = []
        self.element_times: list[np.ndarray] = []
        self.started = time.time()

    def add(self, frame: Frame) -> bool:
        """Keep ``frame`` (one whose time does not follow the last one's is left out); True
        when the step has all its frames."""
        if self.element_times and frame.t <= float(self.element_times[-1][0]):
            return False
        self.values.append(np.array(frame.values, dtype=np.float64))
        self.element_times.append(np.array(frame.element_times, dtype=np.float64))
        return len(self.values) >= self.target

    def recording(self, monitor: Monitor, meta: dict[str, Any]) -> Recording:
        """What was kept, as a capacitance recording."""
        x = np.vstack(self.values)
        et = np.vstack(self.element_times)
        valid = np.isfinite(x)
        return Recording(
            np.where(valid, x, 0.0),
            et[:, 0],
            monitor.layout,
            monitor.source.quantity,
            monitor.source.unit,
            valid=valid,
            element_times=et,
            meta=meta,
        )


class PageCalibration:
    """The calibration steps of a running :class:`Monitor` (see the module docstring).

    Parameters
    ----------
    monitor : Monitor
        A monitor of a capacitance source; its frames are tapped from now on.
    """

    def __init__(self, monitor: Monitor) -> None:
        self.monitor = monitor
        self.recordings: dict[str, Recording] = {}
        self.pressures: dict[str, float] = {}
        self.session: CalibrationSession | None = None
        self.material: str | None = None
        self.report: CheckReport | None = None
        self.capture: _Capture | None = None
        self.saved: dict[str, Any] | None = None
        self.refused: str | None = None
        self.busy: str | None = None  # a fit, check or save running in a worker thread
        self._task: asyncio.Task[None] | None = None
        monitor.taps.append(self._on_frame)

    # ------------------------------------------------------------------ state
    @property
    def available(self) -> bool:
        """Whether the source reads capacitance (pressure sources need no calibration)."""
        return self.monitor.source.quantity == "capacitance"

    def default_material(self) -> str | None:
        """The spacer the device announced, if it is a preset."""
        announced = getattr(self.monitor.source, "announced", {}) or {}
        spacer = announced.get("spacer")
        return str(spacer) if spacer in SPACER_PRESETS else None

    def set_orientation(self, kind: str, edge: str = "top") -> dict[str, str]:
        """How the mat lies: ``kind`` ``bed``, ``seat`` or ``foot`` (``none``: unknown) with
        its head, front or toes at ``edge`` (``top``, ``bottom``, ``left``, ``right``, or
        ``press``: the edge nearest to where a hand presses now, against the empty mat of
        step 1). Applies to the live map now and to the calibration when it is saved."""
        if kind == "none":
            found: dict[str, str] = {}
        else:
            if edge == "press":
                zero = self.recordings.get("zero")
                latest = self.monitor.latest
                if zero is None or latest is None:
                    raise StepError(
                        "finding the edge by a press needs the empty mat (step 1) first"
                    )
                raw = np.array([np.nan if v is None else v for v in latest["raw"]], np.float64)
                edge = edge_of_press(raw, typical_reading(zero), self.monitor.layout)
            found = orientation_toward(kind, edge)
        self.monitor.set_orientation(found)
        chain = None if self.session is None else self.session.chain
        if chain is not None:
            chain.orientation = found
        return found

    def done(self) -> list[str]:
        """The steps done so far, in order."""
        out: list[str] = [s for s in ("zero", "uniform") if s in self.recordings]
        if self.session is not None and self.session.chain is not None:
            out.append("material")
        if self.report is not None:
            out.append("check")
        if self.saved is not None:
            out.append("save")
        return out

    def state(self) -> dict[str, Any]:
        """Everything the page's panel shows, JSON-ready."""
        cap = self.capture
        findings = [] if self.session is None else self.session.findings
        return {
            "done": self.done(),
            "calibrated": not self.monitor.raw_only,
            "available": self.available,
            "steps": list(STEPS),
            "recording": None
            if cap is None
            else {"step": cap.step, "frames": len(cap.values), "of": cap.target},
            "busy": self.busy,
            "recordings": {
                k: {
                    "frames": r.n_frames,
                    "span_s": round(r.duration_s, 3),
                    "pressure_ncm2": self.pressures.get(k),
                    "median_pF": _median(r),
                }
                for k, r in self.recordings.items()
            },
            "orientation": self.monitor.layout.orientation,
            "presets": list(SPACER_PRESETS),
            "default_material": self.default_material(),
            "material": self.material,
            "refused": self.refused,
            "findings": [{"level": f.level, "text": f.text} for f in findings],
            "fit": self._fit_summary(),
            "check": None if self.report is None else _report_dict(self.report),
            "saved": self.saved,
            "defaults": {"frames": DEFAULT_FRAMES, "pressure": "1 N/cm2", "max_frames": MAX_FRAMES},
        }

    def _fit_summary(self) -> dict[str, Any] | None:
        """The chain fitted in step 3: material, stages, id, range of the gains (eq. 2.1)."""
        chain = None if self.session is None else self.session.chain
        if chain is None:
            return None
        convert = chain.find(Convert)
        gain = (
            [1.0, 1.0]
            if convert is None
            else [float(convert.gain_.min()), float(convert.gain_.max())]
        )
        return {
            "material": self.material,
            "stages": list(chain.names),
            "id": chain.id,
            "gain": [round(g, 4) for g in gain],
        }

    # ------------------------------------------------------------------ steps
    def _need(self, step: str) -> None:
        """Refuse ``step`` out of order or while a step runs."""
        if not self.available:
            raise StepError(
                f"{self.monitor.source.name} reads {self.monitor.source.quantity}, not "
                "capacitance: there is nothing to calibrate"
            )
        if self.capture is not None:
            raise StepError(f"{STEP_TEXT[self.capture.step]} is still recording: wait for it")
        if self.busy is not None:
            raise StepError(f"{STEP_TEXT[self.busy]} is still running: wait for it")
        before = STEPS[: STEPS.index(step)]
        missing = [s for s in before if s not in self.done() and s != "check"]
        if missing:
            raise StepError(f"{STEP_TEXT[step]} comes after {STEP_TEXT[missing[0]]}: do that first")

    def _discard_after(self, step: str) -> None:
        """Doing ``step`` again: what followed it no longer holds."""
        later = STEPS[STEPS.index(step) :]
        for s in later:
            self.recordings.pop(s, None)
            self.pressures.pop(s, None)
        if "material" in later:
            self.session, self.material, self.refused = None, None, None
        if "check" in later:
            self.report = None
        self.saved = None

    def record(self, step: str, frames: int = DEFAULT_FRAMES, pressure: str | None = None) -> None:
        """Start keeping ``frames`` frames of the live stream for ``step`` (``zero``,
        ``uniform`` with its load ``pressure``, ``check`` with its load); they come with the
        next frames (:meth:`state` shows how many)."""
        if step not in RECORDED:
            raise ParameterError(
                f"unknown step {step!r}; the recorded steps: {', '.join(RECORDED)}"
            )
        if not 1 <= frames <= MAX_FRAMES:
            raise ParameterError(f"frames must lie in 1..{MAX_FRAMES}, got {frames}")
        p = None
        if step != "zero":
            if pressure is None or not str(pressure).strip():
                raise ParameterError(f"{STEP_TEXT[step]} needs its load, e.g. '1 N/cm2'")
            p = parse_pressure(pressure)
        self._need(step)
        self._discard_after(step)
        self.capture = _Capture(step, frames, p)
        log.info("calibration: recording %d frames of %s", frames, STEP_TEXT[step])

    def cancel(self) -> None:
        """Stop a step's recording (what it kept is dropped)."""
        self.capture = None

    def reset(self) -> None:
        """Start over (a calibration in use stays in use)."""
        if self.busy is not None:
            raise StepError(f"{STEP_TEXT[self.busy]} is still running: wait for it")
        self.capture = None
        self._discard_after("zero")

    def _on_frame(self, frame: Frame) -> None:
        cap = self.capture
        if cap is None or not cap.add(frame):
            return
        meta: dict[str, Any] = {
            "source": self.monitor.source.name,
            "recorded_by": "texsense monitor (calibration panel)",
            "started_at": cap.started,
        }
        meta.update(getattr(self.monitor.source, "announced", {}) or {})
        meta["calibration_step"] = cap.step
        if cap.pressure_ncm2 is not None:
            meta["load_ncm2"] = cap.pressure_ncm2
        self.recordings[cap.step] = cap.recording(self.monitor, meta)
        if cap.pressure_ncm2 is not None:
            self.pressures[cap.step] = cap.pressure_ncm2
        self.capture = None
        log.info("calibration: recorded %s (%d frames)", STEP_TEXT[cap.step], cap.target)
        if cap.step == "check":  # read it through the new chain at once
            self.busy = "check"
            try:
                loop = asyncio.get_running_loop()
            except RuntimeError:  # called outside the server (a script, a test)
                self._check()
            else:
                self._task = loop.create_task(self._check_in_thread())

    async def fit(self, material: str) -> None:
        """Step 3: check the recordings and fit the chain for the spacer preset ``material``
        (in a worker thread: the live frames go on). A refusal is kept in :attr:`refused`
        and raised (:class:`ParameterError`, every reason)."""
        if material not in SPACER_PRESETS:
            raise ParameterError(
                f"unknown material {material!r}; the spacer presets: {', '.join(SPACER_PRESETS)}"
            )
        self._need("material")
        self._discard_after("material")
        zero, uniform = self.recordings["zero"], self.recordings["uniform"]
        names = ("the empty-mat recording (step 1)", "the uniform-load recording (step 2)")

        def make() -> None:  # in the worker thread: the preset's record and the fit take s
            session = CalibrationSession(material, self.pressures["uniform"])
            self.session = session  # its findings are shown even when the fit is refused
            session.fit(zero, uniform, names)

        self.busy, self.material = "material", material
        try:
            await blocking(make)
        except ParameterError as e:
            self.refused = str(e)
            raise
        except Exception as e:  # a fit that fails otherwise: said in one line, no traceback
            self.refused = f"the fit failed: {e}"
            log.warning("calibration: %s", self.refused)
            raise ParameterError(self.refused) from None
        finally:
            self.busy = None

    def _check(self) -> None:
        """Step 4's recording read through the new chain, per element (after the uniform
        load, which came before it on the same clock: the spacer's history)."""
        try:
            assert self.session is not None  # _need("check") saw the fit
            self.report = self.session.check(
                self.recordings["check"], self.pressures["check"], self.recordings["uniform"]
            )
        except Exception as e:  # said on the page, never a traceback in the server
            self.refused = f"the check failed: {e}"
            log.warning("calibration: %s", self.refused)
        finally:
            self.busy = None

    async def _check_in_thread(self) -> None:
        await blocking(self._check)

    async def save(self) -> dict[str, Any]:
        """Step 5: write the chain and the step recordings (new names in the monitor's
        recordings folder) and switch the monitor to calibrated pressure."""
        self._need("save")
        if self.saved is not None:
            raise StepError(
                f"this calibration is saved already ({self.saved['calibration']}) and in use"
            )
        session = self.session
        assert session is not None and session.chain is not None  # _need checked the fit
        chain = session.chain
        chain.orientation = self.monitor.layout.orientation  # how the mat lies, if known
        folder = self.monitor.record_dir
        stem = _unused_stem(
            folder, f"calibration-{time.strftime('%Y%m%d-%H%M%S')}", self.recordings
        )
        self.busy = "save"
        try:
            paths = await blocking(_write, folder, stem, chain, self.recordings)
            pipeline = Pipeline(chain, self.monitor.layout)
        finally:
            self.busy = None
        self.monitor.use_calibration(pipeline, paths["calibration"])
        self.saved = {
            "calibration": str(paths["calibration"]),
            "recordings": {k: str(v) for k, v in paths.items() if k != "calibration"},
            "calibration_id": chain.id,
            "material": self.material,
            "checked": self.report is not None,
        }
        return self.saved


def _unused_stem(folder: Path, stem: str, recordings: dict[str, Recording]) -> str:
    """``stem``, or ``stem-2``, ``stem-3``, ... none of whose files exist yet."""
    k = 1
    while True:
        candidate = stem if k == 1 else f"{stem}-{k}"
        names = [f"{candidate}.json", *(f"{candidate}-{s}.h5" for s in recordings)]
        if all(unused_name(folder / n) == folder / n for n in names):
            return candidate
        k += 1


def _write(
    folder: Path, stem: str, chain: StageChain, recordings: dict[str, Recording]
) -> dict[str, Path]:
    """The step recordings and then the chain (atomic writes: texsense.data.files)."""
    make_folder(folder, "recordings folder")
    out: dict[str, Path] = {}
    for step, rec in recordings.items():
        out[step] = rec.save(unused_name(folder / f"{stem}-{step}.h5"))
    out["calibration"] = chain.save(unused_name(folder / f"{stem}.json"))
    return out


def _median(rec: Recording) -> float | None:
    x = np.where(rec.valid, rec.frames.astype(np.float64), np.nan)
    return round(float(np.nanmedian(x)), 4) if np.isfinite(x).any() else None


def _report_dict(report: CheckReport) -> dict[str, Any]:
    """A check report, JSON-ready: per element its median and relative error (None where it
    failed), the elements off by more than the tolerance (worst first) and the report's lines."""

    def listed(a: np.ndarray, nd: int) -> list[float | None]:
        return [round(float(v), nd) if np.isfinite(v) else None for v in a]

    working = report.working
    med = float(np.median(report.median_ncm2[working])) if working.any() else float("nan")
    size = np.where(working, np.abs(np.nan_to_num(report.error)), -1.0)
    worst = [int(k) for k in np.argsort(-size)[:WORST] if working[k]]
    return {
        "pressure_ncm2": report.pressure_ncm2,
        "median_ncm2": listed(report.median_ncm2, 4),
        "error": listed(report.error, 4),
        "off": [
            {"element": int(k), "name": report.names[k], "error": round(float(report.error[k]), 4)}
            for k in report.off
        ],
        "worst": [
            {"element": k, "name": report.names[k], "error": round(float(report.error[k]), 4)}
            for k in worst
        ],
        "failed": [int(k) for k in np.flatnonzero(~working)],
        "working": int(working.sum()),
        "mat_median_ncm2": round(med, 4) if np.isfinite(med) else None,
        "tolerance": CHECK_TOLERANCE,
        "passed": bool(report.passed),
        "lines": report.lines(),
    }
