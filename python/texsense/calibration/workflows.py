"""Workflows that build a mat calibration — a :class:`~texsense.compensation.stages.StageChain` —
in one place (docs/pipeline.md):

- :func:`calibrate_mat`: a mat from its recordings, as ``texsense calibrate mat`` does —
  the material curve and spacer model from a test-machine record, zeroing and equilibration
  from two mat recordings, and optionally a drift stage from step-and-hold records;
- :func:`calibrate_virtual_mat` and :func:`seat_calibration`: the virtual mats of the
  simulator calibrated the same way, as a user would calibrate them;
- :func:`processed_bed_night`: a simulated night on the virtual bed, read by the mat and
  compensated with its calibration (what a monitor would have recorded; docs/report.md).

The simulator (:mod:`texsense.sim`) knows nothing of calibration or compensation: it is the
ground truth that these workflows and the compensation are graded against.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from texsense.compensation.drift import DriftModel, split_steps
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import Drift, Hysteresis, StageChain
from texsense.data.fitcache import remembered
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError
from texsense.sensor.materials import PRESETS
from texsense.sim import protocols
from texsense.sim.bed import Sleeper, bed_layout, bed_mat, bed_session, night_plan
from texsense.sim.mat import VirtualMat
from texsense.sim.muscle import HIGH_RATE_CDC, sleeve_layout
from texsense.sim.stocking import strip_layout

__all__ = [
    "bed_calibration",
    "calibrate_mat",
    "calibrate_virtual_mat",
    "material_preset",
    "material_record",
    "processed_bed_night",
    "seat_calibration",
    "sleeve_calibration",
    "strip_calibration",
]


#: Calibrate a mat from its recordings (what ``texsense calibrate mat`` runs): detect, convert
#: (eq. 2.1 per element: zeroing and equilibration), hysteresis (the spacer model from the
#: material record, eq. 4.15-4.22) and, with held ``steps``, drift (eq. 5.8); see
#: :meth:`texsense.compensation.stages.StageChain.fit_mat`.
calibrate_mat = StageChain.fit_mat


def material_record(rec: Recording) -> dict[str, np.ndarray]:
    """The material record of one element from a simulated test-machine recording
    (``texsense simulate``): compression, capacitance and pressure columns."""
    return {
        "compression_mm": np.asarray(rec.labels["compression_mm"], dtype=np.float64),
        "capacitance_pF": rec.frames[:, 0].astype(np.float64),
        "pressure_ncm2": np.asarray(rec.labels["pressure_ncm2"], dtype=np.float64),
    }


#: The seed of the reference specimen whose test-machine records a material preset holds.
PRESET_SPECIMEN = 11


def material_preset(name: str) -> tuple[dict[str, np.ndarray], float, Drift]:
    """A spacer preset's material: (material record, thickness mm, drift stage), what
    ``texsense calibrate mat --material NAME`` uses in place of a test-machine record.

    The records are those of the simulator's reference specimen of that spacer
    (:data:`texsense.sensor.materials.PRESETS`, seed :data:`PRESET_SPECIMEN`): the virtual sensor's
    materials. The drift stage's γ is fitted on an hour of the §4.5 validation cycles of that
    specimen (:meth:`DriftModel.fit_history` on the Preisach model's output): γ from held
    steps over-corrects the cyclic loads of a mat in use by 11 % on the virtual seat
    (docs/pipeline.md, docs/drift.md). A real mat of another spacer needs its own record
    (docs/calibration.md)."""
    if name not in PRESETS:
        raise ParameterError(f"unknown spacer preset {name!r}; known: {', '.join(PRESETS)}")
    m = material_record(
        protocols.run_protocol("calibration", name, seed=PRESET_SPECIMEN, sample_hz=None)
    )
    hyst = Hysteresis().fit(m["compression_mm"], m["pressure_ncm2"])
    cycles = protocols.run_protocol(
        "validation", name, seed=PRESET_SPECIMEN, sample_hz=10, cycles=240
    )
    hour = cycles.times < 3600
    predicted = hyst.model_.predict(cycles.labels["compression_mm"][hour])
    drift = DriftModel.fit_history(
        predicted, cycles.labels["pressure_ncm2"][hour], cycles.times[hour]
    )
    # the hour of cycles is held out from the hysteresis fit: the scale of the bounds
    m["held_out_compression_mm"] = cycles.labels["compression_mm"][hour]
    m["held_out_pressure_ncm2"] = cycles.labels["pressure_ncm2"][hour]
    return m, float(PRESETS[name].thickness_mm), Drift.of(drift)


def calibrate_virtual_mat(mat: VirtualMat, material_seed: int = 11) -> StageChain:
    """Calibrate a virtual mat (textile-3mm spacer) as a user would: zeroing and 1 N/cm²
    equilibration scanned on ``mat`` (pass a fresh mat with the same seed as the one to be
    used: the scans load it), the spacer model from a test-machine record of another
    specimen (``material_seed``) with γ from its held steps."""
    n = mat.layout.n_elements
    ft = mat.cdc.frame_time_s(n)
    base = mat.scan(np.arange(10) * ft, np.zeros((10, n))).capacitance
    uni = mat.scan((11 + np.arange(10)) * ft, np.full((10, n), 1.0)).capacitance
    m = protocols.run_protocol("calibration", "textile-3mm", seed=material_seed, sample_hz=None)
    st = protocols.run_protocol("steps", "textile-3mm", seed=material_seed, sample_hz=10)
    steps = split_steps(st.times, st.labels["pressure_ncm2"], st.labels["compression_mm"])
    record = material_record(m)
    # the held steps are not in the hysteresis fit: the scale of the bounds
    record["held_out_compression_mm"] = st.labels["compression_mm"]
    record["held_out_pressure_ncm2"] = st.labels["pressure_ncm2"]
    return calibrate_mat(record, base, uni, 1.0, 3.0, steps=steps)


def _cached(name: str, fit: Callable[[], StageChain]) -> StageChain:
    """The calibration ``fit()`` makes (seconds of Preisach identification, the same every
    time for the same code), made once per version of the code
    (:func:`texsense.data.fitcache.remembered`: kept in memory and in the cache folder; a
    kept file that cannot be read is fitted again and a cache that cannot be written is
    skipped, each said in the log)."""
    return remembered(
        "calibration",
        [name],
        lambda: fit().to_dict(),
        lambda content: StageChain.from_dict(content, "the fit cache"),
    )


def seat_calibration(mat_seed: int = 5, material_seed: int = 11) -> StageChain:
    """Calibrate the virtual seat as a user would (docs/pipeline.md): zeroing + 1 N/cm²
    equilibration of a mat with the same ``mat_seed`` (the same elements), the spacer model
    from a test-machine record of another specimen (``material_seed``) with γ from its held
    steps. Cached (:func:`_cached`)."""
    return _cached(
        f"seat-{mat_seed}-{material_seed}",
        lambda: calibrate_virtual_mat(VirtualMat.seat(seed=mat_seed), material_seed),
    )


def bed_calibration(material_seed: int = 11) -> StageChain:
    """Calibrate the virtual 64 x 32 bed mat (:class:`texsense.monitor.virtual.VirtualBedSource`
    and the station's virtual beds: the same physical mat) as a user would. Cached
    (:func:`_cached`)."""
    return _cached(
        f"bed-{material_seed}",
        lambda: calibrate_virtual_mat(bed_mat(failures=False), material_seed),
    )


def strip_calibration(seed: int = 0, material_seed: int = 11) -> StageChain:
    """Calibrate the stocking sensor strip (:func:`texsense.sim.stocking.strip_layout`, the
    same physical strip as ``wear(..., seed=seed)``) as a user would."""
    return calibrate_virtual_mat(
        VirtualMat(strip_layout(), "textile-3mm", seed=seed), material_seed
    )


def sleeve_calibration(seed: int = 0, material_seed: int = 11) -> StageChain:
    """Calibrate the muscle sleeve (:func:`texsense.sim.muscle.sleeve_layout`, high-rate
    readout, the same physical sleeve as ``session(..., seed=seed)``) as a user would."""
    mat = VirtualMat(sleeve_layout(), "textile-3mm", cdc=HIGH_RATE_CDC, seed=seed)
    return calibrate_virtual_mat(mat, material_seed)


def processed_bed_night(
    hours: float = 8.0, frame_s: float = 10.0, seed: int = 0, turn_every_min: float = 120.0
) -> Recording:
    """A night of a simulated person on the virtual bed (positions held 20 min to 2 h 12 min,
    sitting up and getting out of bed now and then; :func:`texsense.sim.bed.night_plan`), a
    frame every ``frame_s`` s, read by the textile mat with its failing elements and
    compensated by the pipeline with :func:`bed_calibration`: pressure in N/cm², ``valid``
    False where an element was repaired, the true ``side`` of every frame as a label, and the
    settings a bed monitor would declare (``meta``: mode, orientation, alerts)."""

    rng = np.random.default_rng([seed, 7])
    plan: list[tuple[str, float]] = []
    while sum(d for _, d in plan) < hours * 3600:
        plan += night_plan(rng, 4, 3600.0, sit_every=4, out_every=4, away_s=600.0,
                           spread=(0.33, 2.2))  # fmt: skip
    cut, total = [], 0.0
    for position, seconds in plan:
        cut.append((position, min(seconds, hours * 3600 - total)))
        total += seconds
        if total >= hours * 3600:
            break
    night = bed_session(Sleeper.random(seed), cut, seed=seed, mat=bed_mat(), frame_s=frame_s)
    assert night.capacitance is not None
    pressure = Pipeline(bed_calibration(), bed_layout()).run(night.capacitance)
    meta = {
        **pressure.meta,
        "source": f"virtual bed night (person {seed}, {hours:g} h, a frame every {frame_s:g} s)",
        "mode": "bed",
        "orientation": bed_layout().orientation,
        "alerts": {"threshold_mmhg": 32.0, "reposition_min": 20.0, "offload_min": 1.0,
                   "turn_every_min": turn_every_min},
    }  # fmt: skip
    labels = {**pressure.labels, "side": night.truth.labels["side"]}
    return Recording(pressure.frames, pressure.times, pressure.layout, "pressure",
                     pressure.unit, valid=pressure.valid, labels=labels, meta=meta)  # fmt: skip
