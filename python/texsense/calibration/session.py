"""Calibrating a new mat step by step (docs/calibration.md): what ``texsense calibrate mat``,
``texsense calibrate wizard`` and the monitor page's calibration panel share.

The steps are the thesis's (§3.4.1, §6.1): zeroing (nothing on the mat), equilibration (a
uniform known load on every element: eq. 2.1's offset and gain per element), the spacer's
material (a test-machine record, or a preset: the curve, the hysteresis model, eq. 4.15-4.22,
and the drift, eq. 5.8), then a check with another known load, reported per element.
:class:`CalibrationSession` holds the recordings of the steps and makes the one calibration
object of texsense, a :class:`~texsense.compensation.stages.StageChain`; every input is checked
first (:mod:`texsense.calibration.checks`).

Examples
--------
>>> s = CalibrationSession("textile-3mm", pressure="1 N/cm2")
>>> s.thickness_mm, round(s.expected_change_pF(1.0), 2) > 0
(3.0, True)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from texsense.calibration.checks import (
    Finding,
    check_declared_spacer,
    check_gains,
    check_material,
    check_recordings,
    parse_pressure,
    raise_if_refused,
    record_thickness_mm,
    typical_reading,
)
from texsense.calibration.workflows import calibrate_mat, material_preset
from texsense.compensation.conversion import material_curve, rising_compression
from texsense.compensation.drift import read_steps
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import Convert, Drift, StageChain
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError
from texsense.io.columns import read_columns
from texsense.sensor.materials import PRESETS as SPACER_PRESETS

__all__ = ["CalibrationSession", "CheckReport", "load_material"]

#: A check passes for an element within this share of the known load.
CHECK_TOLERANCE = 0.10


def load_material(
    material: str, thickness_mm: float | None = None, drift: Path | None = None
) -> tuple[dict[str, np.ndarray], float, list[Any] | Drift | None, str]:
    """What ``--material`` names: (record, thickness mm, the drift: held steps, a fitted
    stage or None, a name for it).

    A spacer preset (``textile-3mm``, ...; :func:`texsense.calibration.workflows.material_preset`)
    brings its thickness and its drift stage (γ from cycles); a test-machine record CSV needs
    ``thickness_mm`` (the error says what the record's capacitance implies) and takes held
    steps from ``drift``."""
    path = Path(material)
    if material in SPACER_PRESETS and not path.exists():
        record, thickness, preset_drift = material_preset(material)
        if thickness_mm is not None:  # a preset knows its own: taken and ignored otherwise
            raise ParameterError(
                "--thickness-mm has no effect here: it applies to a test-machine record "
                f"(--material RECORD.csv); the preset {material} is {thickness:g} mm thick"
            )
        found: list[Any] | Drift = preset_drift if drift is None else read_steps(drift)
        return record, thickness, found, f"the preset {material}"
    if not path.exists():
        raise ParameterError(
            f"--material {material}: no such file, and not a spacer preset (presets: "
            f"{', '.join(SPACER_PRESETS)})"
        )
    record = read_columns(path, required=("compression_mm", "capacitance_pF", "pressure_ncm2"))
    if thickness_mm is None:
        raise ParameterError(
            f"--material {path} is a record: give the spacer's --thickness-mm (its capacitance "
            f"says about {record_thickness_mm(record):.1f} mm)"
        )
    return record, thickness_mm, None if drift is None else read_steps(drift), str(path)


@dataclass
class CheckReport:
    """A known load read through a new calibration, per element."""

    pressure_ncm2: float
    median_ncm2: np.ndarray  # (N,) each element's median over the check, NaN if failed
    names: list[str]

    @property
    def working(self) -> np.ndarray:
        """Elements that read during the check."""
        return np.isfinite(self.median_ncm2)

    @property
    def error(self) -> np.ndarray:
        """Relative error of every element (NaN where it failed)."""
        return self.median_ncm2 / self.pressure_ncm2 - 1.0

    @property
    def off(self) -> np.ndarray:
        """Indices of working elements off by more than :data:`CHECK_TOLERANCE`, worst first."""
        err = np.abs(self.error)
        bad = np.flatnonzero(self.working & (err > CHECK_TOLERANCE))
        return bad[np.argsort(-err[bad])]

    @property
    def passed(self) -> bool:
        """Every working element within the tolerance, and the mat's median too."""
        return bool(self.off.size == 0 and self.working.any())

    def lines(self, worst: int = 8) -> list[str]:
        """The report as lines for a terminal."""
        w = self.working
        med = float(np.median(self.median_ncm2[w])) if w.any() else float("nan")
        out = [
            f"check at {self.pressure_ncm2:g} N/cm²: median of {int(w.sum())} working elements "
            f"{med:.3g} N/cm² ({100 * (med / self.pressure_ncm2 - 1):+.1f} %), "
            f"{w.size - int(w.sum())} failed, {self.off.size} off by more than "
            f"{100 * CHECK_TOLERANCE:.0f} %"
        ]
        for k in self.off[:worst]:
            out.append(
                f"  {self.names[k]:>14}: {self.median_ncm2[k]:.3g} N/cm² "
                f"({100 * self.error[k]:+.0f} %)"
            )
        if self.off.size > worst:
            out.append(f"  ... and {self.off.size - worst} more")
        for k in np.flatnonzero(~w)[:worst]:
            out.append(f"  {self.names[k]:>14}: failed (no valid reading)")
        return out


class CalibrationSession:
    """The recordings and choices of one mat's calibration.

    Parameters
    ----------
    material : str
        A spacer preset name or a test-machine record CSV (:func:`load_material`).
    pressure : str or float
        The uniform load of equilibration: N/cm², or a string with a unit (``10kPa``).
    thickness_mm : float, optional
        The spacer's thickness (a preset knows its own).
    drift : Path, optional
        A step-and-hold CSV for the drift stage (a preset brings its own).
    """

    def __init__(
        self,
        material: str,
        pressure: str | float = 1.0,
        thickness_mm: float | None = None,
        drift: Path | None = None,
    ) -> None:
        self.pressure_ncm2 = parse_pressure(pressure)
        self.material, self.thickness_mm, self.drift, self.material_name = load_material(
            material, thickness_mm, drift
        )
        is_preset = material in SPACER_PRESETS and not Path(material).exists()
        self.preset = material if is_preset else None
        self.zero: Recording | None = None
        self.uniform: Recording | None = None
        self.chain: StageChain | None = None
        self.findings: list[Finding] = check_material(
            self.material, self.thickness_mm, self.pressure_ncm2, self.material_name
        )
        raise_if_refused(self.findings)

    def expected_change_pF(self, pressure_ncm2: float) -> float:
        """How much the material record's element gains under ``pressure_ncm2`` loaded from
        rest (eq. 2.1 on the first-loading curve): what a mat's elements roughly gain too,
        times their gain."""
        e, c = material_curve(self.material["compression_mm"], self.material["capacitance_pF"])
        squeeze = rising_compression(
            self.material["compression_mm"], self.material["pressure_ncm2"], pressure_ncm2
        )
        return float(np.interp(squeeze, e, c) - np.interp(0.0, e, c))

    def fit(
        self, zero: Recording, uniform: Recording, names: tuple[str, str] = ("zero", "uniform")
    ) -> StageChain:
        """Check the two recordings (refused with every reason, or warnings kept in
        :attr:`findings`) and fit the chain (detect, convert, hysteresis, drift)."""
        found = check_recordings(zero, uniform, names)
        if self.preset is not None:
            for rec, name in zip((zero, uniform), names, strict=True):
                if not any("declares the spacer" in f.text for f in found):
                    found += check_declared_spacer(rec, self.preset, name)
        self.findings = [f for f in self.findings if f.level == "warn"] + found
        raise_if_refused(found)
        self.zero, self.uniform = zero, uniform
        fitted = self.drift if isinstance(self.drift, Drift) else None
        steps = self.drift if isinstance(self.drift, list) else None
        self.chain = calibrate_mat(
            self.material,
            zero,
            uniform,
            self.pressure_ncm2,
            self.thickness_mm,
            steps=steps,
            drift=fitted,
        )
        convert = self.chain.find(Convert)
        assert convert is not None  # calibrate_mat always converts
        self.findings += check_gains(convert.gain_, self.material_name)
        return self.chain

    def check(
        self, recording: Recording, pressure: str | float, before: Recording | None = None
    ) -> CheckReport:
        """Read ``recording`` (the mat under another known load) through the new calibration;
        ``before`` (e.g. the uniform recording, if it came just before on the same clock)
        gives the hysteresis and drift stages the history of the load."""
        if self.chain is None:
            raise ParameterError("the check comes after the calibration (fit first)")
        p = parse_pressure(pressure)
        pipe = Pipeline(self.chain, recording.layout)
        run = recording
        ok_before = before is not None and before.times[-1] < recording.times[0]
        if ok_before and before is not None:
            run = Recording.concatenate([before, recording])
        out = pipe.run(run)
        tail = out.select(slice(run.n_frames - recording.n_frames, None))
        median = typical_reading(tail)
        names = [recording.layout.element_name(k) for k in range(recording.n_elements)]
        return CheckReport(p, median, names)
