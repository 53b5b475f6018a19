"""A trained posture classifier with everything needed to use it on new frames: the feature
definition, the layout it was trained on, the class labels and the classifier.

Saved with joblib (scikit-learn's own persistence) inside a versioned envelope; loading
checks the envelope and gives a :class:`~texsense.exceptions.FormatError` naming the file
for anything that is not a texsense posture model. As with every pickle-based format, load
only files you trust.

Examples
--------
>>> import numpy as np
>>> from texsense import Layout
>>> from texsense.apps.posture import FeatureSet, PostureModel
>>> lay = Layout.grid(2, 2, pitch_cm=1.0)
>>> frames = np.array([[1, 0, 0, 0], [0, 0, 0, 1]] * 10, dtype=float)
>>> labels = np.array(["front-left", "back-right"] * 10)
>>> fs = FeatureSet(("centre",), normalise=False)
>>> m = PostureModel(fs, lay, "naive-bayes").fit(frames, labels)
>>> m.predict(np.array([[0.9, 0.1, 0, 0]])).tolist()
['front-left']
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from texsense import __version__
from texsense.apps.posture.features import FeatureSet, mirror_samples
from texsense.data.files import atomic_path, open_regular
from texsense.data.layout import Layout
from texsense.exceptions import FormatError, ParameterError

if TYPE_CHECKING:
    from sklearn.base import BaseEstimator

# scikit-learn (and with it scipy.stats: ~2 CPU-s of import) only where a model is made,
# fitted or read: a monitor without a posture model starts without it

__all__ = ["FORMAT", "VERSION", "PostureModel"]

FORMAT = "texsense.posture-model"
VERSION = 1


class PostureModel:
    """Features + classifier for one layout.

    Parameters
    ----------
    features : FeatureSet
        What to compute from each frame.
    layout : Layout
        The sensor layout frames must have.
    classifier : str or estimator
        A name from :data:`texsense.apps.posture.evaluate.CLASSIFIERS` or an unfitted estimator.
    columns : list of int, optional
        Use only these feature columns (e.g. from forward selection).
    mirror : dict, optional
        Train also on left-right mirrored frames, labelled by this map from a label to the
        label of its mirror image (:func:`texsense.apps.posture.features.mirror_samples`).
    """

    def __init__(
        self,
        features: FeatureSet,
        layout: Layout,
        classifier: str | BaseEstimator = "naive-bayes",
        columns: list[int] | None = None,
        mirror: dict[Any, Any] | None = None,
    ) -> None:
        self.features = features
        self.layout = layout
        self.classifier_name = (
            classifier if isinstance(classifier, str) else type(classifier).__name__
        )
        if isinstance(classifier, str):
            from texsense.apps.posture.evaluate import make_classifier

            classifier = make_classifier(classifier)
        self.estimator = classifier
        self.columns = None if columns is None else [int(c) for c in columns]
        self.mirror = None if mirror is None else {str(k): v for k, v in mirror.items()}
        self.classes_: np.ndarray | None = None

    def features_of(self, frames: npt.ArrayLike, back: npt.ArrayLike | None = None) -> np.ndarray:
        """The (selected) feature matrix of frames (T, N)."""
        X = self.features.transform(frames, self.layout, back)
        return X if self.columns is None else X[:, self.columns]

    def fit(
        self,
        frames: npt.ArrayLike,
        labels: npt.ArrayLike,
        back: npt.ArrayLike | None = None,
        groups: npt.ArrayLike | None = None,
    ) -> PostureModel:
        """Train on frames (T, N) with one label per frame (and their mirror images when the
        model has a ``mirror`` map). ``groups`` (the subject of every frame) reach a
        classifier that chooses its set-up by subject (``auto``)."""
        y = np.asarray(labels)
        X = self.features_of(frames, back)
        if y.shape != (X.shape[0],):
            raise ParameterError(f"expected {X.shape[0]} labels, got shape {y.shape}")
        g = None if groups is None else np.asarray(groups).astype(str)
        if g is not None and g.shape != y.shape:
            raise ParameterError(f"expected {y.size} groups, got shape {g.shape}")
        if self.mirror is not None:
            flipped, y_m, source = mirror_samples(frames, y, self.layout, self.mirror)
            b = None if back is None else np.asarray(back)[source]
            X = np.vstack([X, self.features_of(flipped, b)])
            y = np.concatenate([y, y_m])
            g = None if g is None else np.concatenate([g, g[source]])
        from texsense.apps.posture.evaluate import check_classes, takes_groups

        check_classes(y, "the training frames")
        if takes_groups(self.estimator):
            self.estimator.fit(X, y, groups=g)
        else:
            self.estimator.fit(X, y)
        self.classes_ = np.unique(y)
        return self

    def predict(self, frames: npt.ArrayLike, back: npt.ArrayLike | None = None) -> np.ndarray:
        """The posture of every frame."""
        if self.classes_ is None:
            raise ParameterError("the posture model is not trained: call fit() first")
        return self.estimator.predict(self.features_of(frames, back))

    def predict_with_confidence(
        self, frames: npt.ArrayLike, back: npt.ArrayLike | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The posture of every frame and the classifier's probability for it (NaN for a
        classifier without probabilities)."""
        if self.classes_ is None:
            raise ParameterError("the posture model is not trained: call fit() first")
        X = self.features_of(frames, back)  # once for both (a live bed frame: 25 ms each)
        from sklearn.calibration import CalibratedClassifierCV

        if isinstance(self.estimator, CalibratedClassifierCV):
            # its predict is the class of the highest probability: computed once, not twice
            # (half of a live bed frame's cost in the station, issue 33)
            p = self.estimator.predict_proba(X)
            return self.estimator.classes_[np.argmax(p, axis=1)], p.max(axis=1)
        label = self.estimator.predict(X)
        proba = getattr(self.estimator, "predict_proba", None)
        if proba is None:
            return label, np.full(label.shape, np.nan)
        try:
            p = proba(X)
        except AttributeError:  # e.g. an SVC trained without probability=True
            return label, np.full(label.shape, np.nan)
        return label, p.max(axis=1)

    def save(self, path: str | Path) -> Path:
        """Write the model (joblib, versioned envelope)."""
        import joblib

        if self.classes_ is None:
            raise ParameterError("only a trained posture model can be saved")
        path = Path(path)
        envelope: dict[str, Any] = {
            "format": FORMAT,
            "version": VERSION,
            "software": __version__,
            "features": self.features.to_dict(),
            "layout": self.layout.to_dict(),
            "classifier": self.classifier_name,
            "columns": self.columns,
            "mirror": self.mirror,
            "classes": self.classes_,
            "estimator": self.estimator,
        }
        with atomic_path(path) as tmp:  # a reader never sees half a model
            joblib.dump(envelope, tmp)
        return path

    @classmethod
    def load(cls, path: str | Path) -> PostureModel:
        """Read a model written by :meth:`save`."""
        import joblib

        path = Path(path)
        try:
            with open_regular(path) as f:  # (a FIFO or a device is refused, never waited on)
                d = joblib.load(f)
        except FormatError:
            raise
        except Exception as e:  # joblib raises many kinds for a file that is not its own
            raise FormatError(path, f"not a texsense posture model ({type(e).__name__})") from None
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise FormatError(path, f"not a texsense posture model (expected format {FORMAT!r})")
        if d.get("version") != VERSION:
            raise FormatError(
                path, f"posture model version {d.get('version')!r}; this software reads {VERSION}"
            )
        missing = [
            k for k in ("features", "layout", "classes", "estimator", "classifier") if k not in d
        ]
        if missing:
            raise FormatError(path, f"posture model lacks {', '.join(missing)}")
        model = cls(
            FeatureSet.from_dict(d["features"]),
            Layout.from_dict(d["layout"]),
            d["estimator"],
            d.get("columns"),
            d.get("mirror"),
        )
        model.classifier_name = d["classifier"]
        model.classes_ = np.asarray(d["classes"])
        return model
