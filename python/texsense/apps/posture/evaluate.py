"""Classifiers, leave-one-subject-out evaluation, sequential forward selection and the
Mahalanobis distances between posture classes (thesis §6.3-6.4).

- :data:`CLASSIFIERS`: the thesis's Gaussian naive Bayes (§6.3.1, eq. 6.1-6.8) and stronger
  scikit-learn classifiers for comparison; :func:`make_classifier` builds one by name.
- :func:`loso`: leave-one-subject-out accuracy (§6.5.2: train on all subjects but one, test on
  that one, average over subjects), per subject and as a confusion matrix. The held-out
  subject is never seen in training (tested).
- :func:`sequential_forward_selection`: §6.3.2 / fig. 6.5, cost = LOSO accuracy.
- :func:`class_distances`: d_md (eq. 6.9) and d_ms (eq. 6.10-6.11).

Examples
--------
>>> import numpy as np
>>> rng = np.random.default_rng(0)
>>> y = np.repeat([0, 1], 40); groups = np.tile(np.repeat(["s1", "s2", "s3", "s4"], 10), 2)
>>> X = np.c_[y + 0.3 * rng.standard_normal(80), rng.standard_normal(80)]
>>> report = loso(X, y, groups, "naive-bayes")
>>> report.accuracy > 0.9, sorted(report.per_subject)
(True, ['s1', 's2', 's3', 's4'])
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from sklearn.base import BaseEstimator, ClassifierMixin, clone
from sklearn.utils.metaestimators import available_if

from texsense._progress import progress
from texsense.exceptions import ParameterError

__all__ = [
    "CLASSIFIERS",
    "LosoReport",
    "SubjectSelect",
    "check_classes",
    "class_distances",
    "loso",
    "make_classifier",
    "pooled_precision",
    "sequential_forward_selection",
    "takes_groups",
]


def _naive_bayes() -> BaseEstimator:
    from sklearn.naive_bayes import GaussianNB

    return GaussianNB()


def _lda() -> BaseEstimator:
    from sklearn.discriminant_analysis import LinearDiscriminantAnalysis

    return LinearDiscriminantAnalysis(solver="lsqr", shrinkage="auto")


def _logistic() -> BaseEstimator:
    from sklearn.linear_model import LogisticRegression
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    return make_pipeline(StandardScaler(), LogisticRegression(C=1.0, max_iter=3000))


def _linear_svm() -> BaseEstimator:
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler
    from sklearn.svm import SVC

    return make_pipeline(StandardScaler(), SVC(kernel="linear", C=0.01))


def _rbf_svm() -> BaseEstimator:
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler
    from sklearn.svm import SVC

    return make_pipeline(StandardScaler(), SVC(kernel="rbf", C=10.0, gamma="scale"))


def _boosting() -> BaseEstimator:
    from sklearn.ensemble import HistGradientBoostingClassifier

    return HistGradientBoostingClassifier(max_iter=150, learning_rate=0.1, random_state=0)


class SubjectSelect(ClassifierMixin, BaseEstimator):
    """A classifier that chooses its own set-up on the training data: every candidate
    (classifier name, regularisation C) is scored by a ``folds``-fold split *by subject* of
    every ``subsample``-th training sample, the best is refitted on all of them. Given no
    subjects (``groups``) or fewer than ``folds`` of them, it takes the first candidate and
    says so in ``choice_``.

    :func:`loso` and :class:`~texsense.apps.posture.model.PostureModel` pass the subjects, so a
    leave-one-subject-out run of it is nested: the held-out subject never takes part in the
    choice. ``probability=True`` gives a chosen classifier without probabilities
    sigmoid-calibrated ones (for a dashboard's confidence).
    """

    def __init__(
        self,
        candidates: tuple[tuple[str, float | None], ...] = (
            ("logistic", 0.3),
            ("linear-svm", 0.01),
        ),
        folds: int = 3,
        subsample: int = 5,
        probability: bool = False,
    ) -> None:
        self.candidates = candidates
        self.folds = folds
        self.subsample = subsample
        self.probability = probability

    def _make(self, k: int) -> BaseEstimator:
        name, c = self.candidates[k]
        return make_classifier(name, c)

    def fit(
        self, X: npt.ArrayLike, y: npt.ArrayLike, groups: npt.ArrayLike | None = None
    ) -> SubjectSelect:
        """Choose by subject and refit on everything."""
        Xa, ya = np.asarray(X, dtype=np.float64), np.asarray(y)
        if not self.candidates:
            raise ParameterError("SubjectSelect needs at least one candidate")
        subjects = None if groups is None else np.asarray(groups).astype(str)
        scores: list[float] = []
        if subjects is None or np.unique(subjects).size < self.folds:
            best = 0
            self.choice_ = f"{self._label(0)} (fewer than {self.folds} subjects: not chosen)"
        else:
            keep = np.arange(ya.size)[:: max(int(self.subsample), 1)]
            names = np.unique(subjects)
            fold_of = {s: i % self.folds for i, s in enumerate(names)}
            fold = np.array([fold_of[s] for s in subjects[keep]])
            for k in range(len(self.candidates)):
                acc = []
                for f in range(self.folds):
                    test = fold == f
                    if np.unique(ya[keep][~test]).size < 2:
                        continue
                    model = self._make(k).fit(Xa[keep][~test], ya[keep][~test])
                    acc.append(float(np.mean(model.predict(Xa[keep][test]) == ya[keep][test])))
                scores.append(float(np.mean(acc)) if acc else 0.0)
            best = int(np.argmax(scores))
            self.choice_ = f"{self._label(best)} (inner score {scores[best]:.1%})"
        self.scores_ = scores
        self.chosen_ = self._label(best)
        estimator = self._make(best)
        if self.probability and not hasattr(estimator, "predict_proba"):
            from sklearn.calibration import CalibratedClassifierCV

            estimator = CalibratedClassifierCV(estimator, ensemble=False)
        self.estimator_ = estimator.fit(Xa, ya)
        self.classes_ = self.estimator_.classes_
        return self

    def _label(self, k: int) -> str:
        name, c = self.candidates[k]
        return name if c is None else f"{name} C={c:g}"

    def predict(self, X: npt.ArrayLike) -> np.ndarray:
        """Labels of the chosen classifier."""
        return self.estimator_.predict(X)

    def _has_proba(self) -> bool:
        est = getattr(self, "estimator_", None)
        return est is None or hasattr(est, "predict_proba")

    @available_if(_has_proba)
    def predict_proba(self, X: npt.ArrayLike) -> np.ndarray:
        """Probabilities of the chosen classifier (when it has them)."""
        return self.estimator_.predict_proba(X)


def takes_groups(estimator: BaseEstimator) -> bool:
    """Whether ``estimator.fit`` takes the subjects (``groups=``)."""
    return "groups" in inspect.signature(estimator.fit).parameters


#: Classifier factories by name. ``naive-bayes`` is the thesis's (§6.3.1); ``auto`` chooses
#: between logistic regression and a linear SVM by subject on the training data
#: (:class:`SubjectSelect`).
CLASSIFIERS: dict[str, Callable[[], BaseEstimator]] = {
    "naive-bayes": _naive_bayes,
    "lda": _lda,
    "logistic": _logistic,
    "linear-svm": _linear_svm,
    "svm": _rbf_svm,
    "boosting": _boosting,
    "auto": SubjectSelect,
}


#: The classifiers whose regularisation ``c`` can be set, and the parameter that holds it.
C_PARAMETER = {"logistic": "logisticregression__C", "linear-svm": "svc__C", "svm": "svc__C"}


def make_classifier(name: str, c: float | None = None) -> BaseEstimator:
    """A fresh, unfitted classifier by name (see :data:`CLASSIFIERS`), with the
    regularisation ``c`` of a logistic regression or SVM when given (None: the registry's)."""
    if name not in CLASSIFIERS:
        raise ParameterError(f"unknown classifier {name!r}; known: {', '.join(CLASSIFIERS)}")
    estimator = CLASSIFIERS[name]()
    if c is not None:
        if name not in C_PARAMETER:
            raise ParameterError(
                f"{name} has no regularisation C to set (only {', '.join(C_PARAMETER)})"
            )
        if not c > 0:
            raise ParameterError(f"C must be > 0, got {c}")
        estimator.set_params(**{C_PARAMETER[name]: float(c)})
    return estimator


@dataclass
class LosoReport:
    """Result of :func:`loso`."""

    accuracy: float  # mean over subjects of the per-subject accuracy (§6.5.2)
    per_subject: dict[str, float]
    labels: list[Any]
    confusion: np.ndarray  # (true label, predicted label) counts over all subjects
    predictions: np.ndarray = field(repr=False)

    @property
    def minimum(self) -> tuple[str, float]:
        """The worst subject and its accuracy."""
        s = min(self.per_subject, key=self.per_subject.__getitem__)
        return s, self.per_subject[s]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no per-sample predictions)."""
        return {
            "accuracy": self.accuracy,
            "per_subject": self.per_subject,
            "minimum": {"subject": self.minimum[0], "accuracy": self.minimum[1]},
            "labels": [str(v) for v in self.labels],
            "confusion": self.confusion.tolist(),
        }


def check_classes(y: npt.ArrayLike, what: str) -> None:
    """Refuse training frames of one class (scikit-learn's classifiers raise deep inside
    their fit): ``what`` names the frames (``"the frames without subject 's1'"``)."""
    values = np.unique(np.asarray(y).astype(str))
    if values.size < 2:
        one = f"one class, '{values[0]}'" if values.size else "no class"
        raise ParameterError(f"{what} hold {one}: a classifier needs two or more")


def _check_xy(
    X: npt.ArrayLike, y: npt.ArrayLike, groups: npt.ArrayLike, min_groups: int = 2
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    Xa = np.asarray(X, dtype=np.float64)
    ya = np.asarray(y)
    ga = np.asarray(groups).astype(str)
    if Xa.ndim != 2 or ya.shape != (Xa.shape[0],) or ga.shape != (Xa.shape[0],):
        raise ParameterError(
            f"X must be (n, features) and y, groups (n,): got {Xa.shape}, {ya.shape}, {ga.shape}"
        )
    if not np.all(np.isfinite(Xa)):
        raise ParameterError("features contain NaN or infinite values")
    if np.unique(ga).size < min_groups:
        raise ParameterError("leave-one-subject-out needs at least two subjects (groups)")
    return Xa, ya, ga


def loso(
    X: npt.ArrayLike,
    y: npt.ArrayLike,
    groups: npt.ArrayLike,
    classifier: str | BaseEstimator = "naive-bayes",
    *,
    extra: tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike] | None = None,
    show_progress: bool = False,
) -> LosoReport:
    """Leave-one-subject-out accuracy: for every subject, train on the others and test on it.

    Parameters
    ----------
    X : array_like (n, F)
        Features of every sample.
    y : array_like (n,)
        Class labels.
    groups : array_like (n,)
        Subject of every sample.
    classifier : str or estimator
        A name from :data:`CLASSIFIERS` or an unfitted scikit-learn estimator (cloned per
        fold).
    extra : (X, y, groups), optional
        Additional training samples, e.g. mirrored copies
        (:func:`texsense.apps.posture.features.mirror_samples`), each belonging to a subject: they
        join the training set of every fold whose held-out subject is another one, and are
        never tested.
    show_progress : bool
        A progress bar over the subjects.
    """
    Xa, ya, ga = _check_xy(X, y, groups)
    if extra is None:
        Xe, ye, ge = Xa[:0], ya[:0], ga[:0]
    else:
        Xe, ye, ge = _check_xy(*extra, min_groups=0)
        if Xe.shape[1] != Xa.shape[1]:
            raise ParameterError(
                f"extra samples have {Xe.shape[1]} features, the samples {Xa.shape[1]}"
            )
    template = make_classifier(classifier) if isinstance(classifier, str) else classifier
    labels = list(np.unique(ya))
    pred = np.empty_like(ya)
    per_subject: dict[str, float] = {}
    subjects = list(np.unique(ga))
    it = progress(subjects, total=len(subjects), desc="leave one subject out", unit="subject")
    for s in it if show_progress else subjects:
        test = ga == s
        train_extra = ge != s
        check_classes(
            np.concatenate([ya[~test], ye[train_extra]]),
            f"the training frames without subject {str(s)!r}",
        )
        model = clone(template)
        kwargs = {"groups": np.concatenate([ga[~test], ge[train_extra]])} if takes_groups(
            model) else {}  # fmt: skip
        model.fit(
            np.vstack([Xa[~test], Xe[train_extra]]),
            np.concatenate([ya[~test], ye[train_extra]]),
            **kwargs,
        )
        pred[test] = model.predict(Xa[test])
        per_subject[str(s)] = float(np.mean(pred[test] == ya[test]))
    index = {v: i for i, v in enumerate(labels)}
    confusion = np.zeros((len(labels), len(labels)), dtype=np.int64)
    np.add.at(confusion, ([index[v] for v in ya], [index[v] for v in pred]), 1)
    return LosoReport(
        accuracy=float(np.mean(list(per_subject.values()))),
        per_subject=per_subject,
        labels=labels,
        confusion=confusion,
        predictions=pred,
    )


def sequential_forward_selection(
    X: npt.ArrayLike,
    y: npt.ArrayLike,
    groups: npt.ArrayLike,
    k: int,
    classifier: str | BaseEstimator = "naive-bayes",
    *,
    candidates: npt.ArrayLike | None = None,
    show_progress: bool = True,
) -> tuple[list[int], list[float]]:
    """Sequential forward selection (thesis §6.3.2, fig. 6.5): start from the empty set and
    add, one at a time, the feature whose addition gives the highest leave-one-subject-out
    accuracy, until ``k`` features are chosen.

    Returns the chosen column indices in the order they were added and the LOSO accuracy
    after each addition (the thesis picks the k where the accuracy peaks).
    """
    Xa, ya, ga = _check_xy(X, y, groups)
    pool = (
        list(range(Xa.shape[1]))
        if candidates is None
        else [int(c) for c in np.asarray(candidates).ravel()]
    )
    if not 1 <= k <= len(pool):
        raise ParameterError(f"k must lie in 1..{len(pool)}, got {k}")
    chosen: list[int] = []
    scores: list[float] = []
    steps = range(k)
    for _ in (
        progress(steps, total=k, desc="forward selection", unit="feature")
        if show_progress
        else steps
    ):
        best, best_score = -1, -1.0
        for c in pool:
            if c in chosen:
                continue
            score = loso(Xa[:, [*chosen, c]], ya, ga, classifier).accuracy
            if score > best_score:
                best, best_score = c, score
        chosen.append(best)
        scores.append(best_score)
    return chosen, scores


def pooled_precision(X: npt.ArrayLike, y: npt.ArrayLike, ridge: float = 0.05) -> np.ndarray:
    """Inverse of the pooled within-class covariance (with a ridge of ``ridge`` x its mean
    variance, so that it exists with more features than samples): the metric of
    :func:`class_distances` (thesis §6.4.2)."""
    X, y = np.asarray(X, dtype=np.float64), np.asarray(y)
    centred = np.vstack([X[y == c] - X[y == c].mean(axis=0) for c in np.unique(y)])
    dof = max(centred.shape[0] - np.unique(y).size, 1)
    cov = centred.T @ centred / dof
    scale = float(np.mean(np.diag(cov))) or 1.0
    return np.linalg.inv(cov + ridge * scale * np.eye(cov.shape[0]))


def class_distances(
    X: npt.ArrayLike,
    y: npt.ArrayLike,
    *,
    reference: tuple[np.ndarray, np.ndarray] | None = None,
    ridge: float = 0.05,
    precision: np.ndarray | None = None,
) -> tuple[float, float]:
    """Mahalanobis distances between and within classes (thesis §6.4.2).

    ``d_md`` (eq. 6.9) is the mean over all ordered pairs of different classes of the
    Mahalanobis distance between the class means; ``d_ms`` (eq. 6.11) the mean over classes of
    ``d_c`` (eq. 6.10), the mean distance between all pairs of different samples of a class.
    The metric is the pooled within-class covariance of ``reference`` (features, labels) —
    e.g. the training patterns, so that distances of test sets with growing errors are
    measured with one fixed metric — or of (X, y) itself; ``precision`` gives that metric
    directly (:func:`pooled_precision`, computed once for many test sets).

    Returns
    -------
    (d_md, d_ms)
    """
    Xa = np.asarray(X, dtype=np.float64)
    ya = np.asarray(y)
    classes = np.unique(ya)
    if classes.size < 2:
        raise ParameterError("class distances need at least two classes")
    if precision is None:
        rx, ry = reference if reference is not None else (Xa, ya)
        precision = pooled_precision(rx, ry, ridge)

    # d' P d = |L' d|² with P = L L' (Cholesky): distances in whitened coordinates, one
    # product per sample instead of one per pair
    whiten = np.linalg.cholesky(precision)

    def dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        d = (a @ whiten)[:, None, :] - (b @ whiten)[None, :, :]
        return np.sqrt(np.einsum("ijk,ijk->ij", d, d))

    means = np.vstack([Xa[ya == c].mean(axis=0) for c in classes])
    dm = dist(means, means)
    n = classes.size
    d_md = float(dm.sum() / (n * (n - 1)))  # eq. 6.9, the diagonal is 0
    d_c = []
    for c in classes:
        s = Xa[ya == c]
        ns = s.shape[0]
        d_c.append(float(dist(s, s).sum() / (ns * (ns - 1))) if ns > 1 else 0.0)  # eq. 6.10
    return d_md, float(np.mean(d_c))  # eq. 6.11
