"""The error-modelling study of thesis §6.4-6.5.1: how much noise, hysteresis, drift and
element failure a posture classifier tolerates.

One reference pattern per posture (§6.4.1); 32 training patterns per posture with Gaussian
noise of σ 0.05 N/cm²; for every level of an error source 15 test patterns per posture with
that error added; recognition rate of the classifier trained on the training patterns, and
the Mahalanobis distances between (d_md, eq. 6.9) and within (d_ms, eq. 6.10-6.11) the
classes of the test patterns, measured with the training patterns' pooled covariance.

Error sources (§6.4.3-6.4.6):

- **noise**: Gaussian, σ 0.013-1.3 N/cm², uncorrelated between elements;
- **hysteresis**: eq. 6.12 with a pressure-to-pressure Preisach model (from the hysteresis
  issue), on the transitions from every posture to the test posture, scaled by f_h 0.1-2.0;
- **drift**: eq. 6.13, ``p_r2 + (p_r2 - p_r1) γ ln(t + 1)`` with γ = -0.025, t 1-1000 s, on the
  same transitions;
- **failures**: f randomly chosen elements read 0, a different set per test pattern.

Examples
--------
>>> import numpy as np
>>> from texsense import Layout
>>> from texsense.apps.posture.study import ErrorStudy
>>> lay = Layout.grid(4, 4, pitch_cm=2.0)
>>> refs = np.eye(16)[[0, 5, 10, 15]] * 3.0 + 0.5          # four "postures"
>>> study = ErrorStudy(refs, lay, ["a", "b", "c", "d"], seed=0)
>>> low, high = study.sweep("noise", [0.05, 3.0])
>>> low.rate, high.rate < 0.8, high.d_ms > low.d_ms        # noise blurs the classes
(1.0, True, True)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense._progress import progress
from texsense.apps.posture.evaluate import class_distances, make_classifier, pooled_precision
from texsense.apps.posture.features import FeatureSet
from texsense.compensation.hysteresis import HysteresisModel, scale_hysteresis
from texsense.data.layout import Layout
from texsense.exceptions import ParameterError
from texsense.sim import protocols

__all__ = ["DEFAULT_LEVELS", "ErrorStudy", "StudyPoint"]

#: Levels of each error source as in thesis §6.5.1 (failures: fractions of the elements).
DEFAULT_LEVELS: dict[str, list[float]] = {
    "noise": [0.013, 0.05, 0.1, 0.2, 0.3, 0.4, 0.55, 0.68, 0.8, 0.95, 1.1, 1.3],
    "hysteresis": [round(0.1 * k, 1) for k in range(0, 21, 2)],
    "drift": [1.0, 10.0, 30.0, 100.0, 300.0, 1000.0],
    "failures": [0.0, 0.1, 0.25, 0.4, 0.5, 0.6, 0.75, 0.9, 1.0],
}
UNITS = {"noise": "σ [N/cm²]", "hysteresis": "f_h", "drift": "t [s]", "failures": "share failed"}


@dataclass
class StudyPoint:
    """One level of one error source."""

    source: str
    level: float
    rate: float  # recognition rate of the test patterns
    d_md: float  # eq. 6.9
    d_ms: float  # eq. 6.11


class ErrorStudy:
    """Thesis §6.4: classifier tolerance to modelled errors.

    Parameters
    ----------
    references : array_like (C, N)
        One reference pressure pattern per posture, N/cm².
    layout : Layout
        Layout of the patterns.
    labels : sequence
        Posture label of every reference pattern.
    features : FeatureSet, optional
        Default: element values normalised to the mean pressure, centre of force and the 4
        and 16 areas (§6.3.2).
    classifier : str
        Default ``"naive-bayes"`` (§6.3.1).
    hysteresis_model : HysteresisModel, optional
        Pressure-to-pressure Preisach model for the hysteresis source (eq. 6.12).
    gamma : float
        Drift factor of eq. 6.13 (the thesis's -0.025).
    train_noise : float
        σ of the training patterns' noise (0.05 N/cm²).
    n_train, n_test : int
        Patterns per posture (32 and 15).
    """

    def __init__(
        self,
        references: npt.ArrayLike,
        layout: Layout,
        labels: Sequence[Any],
        *,
        features: FeatureSet | None = None,
        classifier: str = "naive-bayes",
        hysteresis_model: Any = None,
        gamma: float = -0.025,
        train_noise: float = 0.05,
        n_train: int = 32,
        n_test: int = 15,
        seed: int = 0,
    ) -> None:
        self.references = np.asarray(references, dtype=np.float64)
        if self.references.ndim != 2 or self.references.shape[1] != layout.n_elements:
            raise ParameterError(
                f"references must be (postures, {layout.n_elements}), got {self.references.shape}"
            )
        self.labels = np.asarray(labels)
        if self.labels.shape != (self.references.shape[0],) or np.unique(self.labels).size < 2:
            raise ParameterError("give one distinct label per reference pattern (at least two)")
        self.layout = layout
        self.features = features or FeatureSet(("elements", "centre", "areas4", "areas16"))
        self.hysteresis_model = hysteresis_model
        self.gamma = gamma
        self.n_test = n_test
        self._rng = np.random.default_rng(seed)
        train = np.repeat(self.references, n_train, axis=0)
        train = np.clip(train + self._rng.normal(0.0, train_noise, train.shape), 0.0, None)
        self.train_y = np.repeat(self.labels, n_train)
        self.train_X = self.features.transform(train, layout)
        self.model = make_classifier(classifier).fit(self.train_X, self.train_y)
        self.metric = pooled_precision(self.train_X, self.train_y)  # one metric for all tests

    # ------------------------------------------------------------------ test patterns
    def _transitions(self) -> tuple[np.ndarray, np.ndarray]:
        """(start, end) pattern pairs: n_test per posture, starting from the other postures
        in turn (§6.4.4, fig. 6.8)."""
        n_c = self.references.shape[0]
        starts, ends = [], []
        for c in range(n_c):
            others = [o for o in range(n_c) if o != c]
            for k in range(self.n_test):
                starts.append(others[k % len(others)])
                ends.append(c)
        return np.array(starts), np.array(ends)

    def test_patterns(self, source: str, level: float) -> tuple[np.ndarray, np.ndarray]:
        """Test patterns (n_test x postures, N) with ``level`` of ``source`` and their labels."""
        r1_idx, r2_idx = self._transitions()
        r1, r2 = self.references[r1_idx], self.references[r2_idx]
        if source == "noise":
            out = np.clip(r2 + self._rng.normal(0.0, level, r2.shape), 0.0, None)
        elif source == "hysteresis":
            if self.hysteresis_model is None:
                raise ParameterError("the hysteresis source needs a hysteresis_model")

            out = scale_hysteresis(self.hysteresis_model, r1, r2, level).reshape(r2.shape)
            out = np.clip(out, 0.0, None)
        elif source == "drift":
            out = np.clip(r2 + (r2 - r1) * self.gamma * np.log(level + 1.0), 0.0, None)  # 6.13
        elif source == "failures":
            n = self.layout.n_elements
            count = round(level * n) if level <= 1 else int(level)
            out = r2.copy()
            for row in out:
                row[self._rng.choice(n, size=min(count, n), replace=False)] = 0.0
        else:
            raise ParameterError(f"unknown error source {source!r}; known: {', '.join(UNITS)}")
        return out, self.labels[r2_idx]

    def point(self, source: str, level: float) -> StudyPoint:
        """Recognition rate and class distances at one level."""
        patterns, y = self.test_patterns(source, level)
        X = self.features.transform(patterns, self.layout)
        rate = float(np.mean(self.model.predict(X) == y))
        d_md, d_ms = class_distances(X, y, precision=self.metric)
        return StudyPoint(source, float(level), rate, d_md, d_ms)

    def sweep(self, source: str, levels: Sequence[float] | None = None) -> list[StudyPoint]:
        """:meth:`point` for every level (default :data:`DEFAULT_LEVELS`)."""
        levels = DEFAULT_LEVELS[source] if levels is None else list(levels)
        return [self.point(source, lv) for lv in levels]

    def run(
        self, sources: Sequence[str] | None = None, *, show_progress: bool = True
    ) -> dict[str, list[StudyPoint]]:
        """All sweeps (hysteresis only with a model), with a progress bar over the points."""
        sources = list(sources or [s for s in UNITS if s != "hysteresis" or self.hysteresis_model])
        jobs = [(s, lv) for s in sources for lv in DEFAULT_LEVELS[s]]
        it = progress(jobs, total=len(jobs), desc="error study", unit="level")
        results: dict[str, list[StudyPoint]] = {s: [] for s in sources}
        for s, lv in it if show_progress else jobs:
            results[s].append(self.point(s, lv))
        return results

    @staticmethod
    def to_dict(results: dict[str, list[StudyPoint]]) -> dict[str, list[dict[str, Any]]]:
        """JSON-ready results."""
        return {s: [asdict(p) for p in pts] for s, pts in results.items()}


def plot_study(results: dict[str, list[StudyPoint]], title: str = "") -> Any:
    """Figures like thesis fig. 6.9-6.12: recognition rate and d_md / d_ms per error source."""
    import matplotlib.pyplot as plt

    n = len(results)
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.4), layout="constrained", squeeze=False)
    for ax, (source, pts) in zip(axes[0], results.items(), strict=True):
        lv = [p.level for p in pts]
        ax.plot(lv, [100 * p.rate for p in pts], "ko-", ms=3, label="recognition rate")
        ax.set_ylim(-2, 102)
        ax.set_xlabel(UNITS.get(source, source))
        ax.set_ylabel("recognition rate [%]")
        ax.set_title(source, fontsize=10)
        ax.grid(alpha=0.3)
        if source in ("noise", "drift"):
            ax.set_xscale("log")
        twin = ax.twinx()
        twin.plot(lv, [p.d_md for p in pts], "s--", color="C0", ms=3, label="d_md (between)")
        twin.plot(lv, [p.d_ms for p in pts], "^--", color="C3", ms=3, label="d_ms (within)")
        twin.set_ylabel("Mahalanobis distance")
        if source == next(iter(results)):
            h1, l1 = ax.get_legend_handles_labels()
            h2, l2 = twin.get_legend_handles_labels()
            ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="lower left")
    if title:
        fig.suptitle(title, fontsize=11)
    return fig


def sensor_hysteresis_model(spacer: str = "textile-3mm", seed: int = 0) -> Any:
    """A pressure-to-pressure Preisach model of a textile sensor for eq. 6.12: input the true
    pressure, output what the sensor reports through its first-loading curve, identified
    (thesis method, §4.3) on the virtual spacer's calibration protocol (rising curve and
    falling curves)."""

    rec = protocols.run_protocol("calibration", spacer, seed=seed, sample_hz=None)
    e = rec.labels["compression_mm"]
    p = rec.labels["pressure_ncm2"]
    top = int(np.argmax(p))
    rise_e, rise_p = np.maximum.accumulate(e[: top + 1]), p[: top + 1]
    keep = np.concatenate([[True], np.diff(rise_e) > 0])
    reading = np.interp(e, rise_e[keep], rise_p[keep])  # the uncompensated sensor
    # the thesis's own hysteresis model for its error study (eq. 6.12), from its protocol
    return HysteresisModel(method="thesis", input_name="pressure_ncm2", input_unit="N/cm2").fit(
        p, reading, remember=True
    )


def study_tables(results: dict[str, list[StudyPoint]]) -> str:
    """Markdown tables of a study: one per error source, levels as columns."""
    out = []
    for source, pts in results.items():
        out.append(f"| {source} | " + " | ".join(f"{p.level:g}" for p in pts) + " |")
        out.append("|---|" + "---:|" * len(pts))
        out.append("| recognition rate | " + " | ".join(f"{p.rate:.0%}" for p in pts) + " |")
        out.append("| d_md | " + " | ".join(f"{p.d_md:.1f}" for p in pts) + " |")
        out.append("| d_ms | " + " | ".join(f"{p.d_ms:.1f}" for p in pts) + " |\n")
    return "\n".join(out)
