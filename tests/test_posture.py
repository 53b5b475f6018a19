import numpy as np
import pytest
from sklearn.base import BaseEstimator, ClassifierMixin

from texsense import Layout
from texsense.apps.posture import (
    FeatureSet,
    PostureModel,
    align_maps,
    area_means,
    centre_of_force,
    class_distances,
    loso,
    mirror_frames,
    mirror_samples,
    sequential_forward_selection,
)
from texsense.exceptions import FormatError, ParameterError


def test_centre_of_force_of_known_maps():
    lay = Layout.grid(3, 4, pitch_cm=2.0)  # x = 1, 3, 5, 7 cm; y = 1, 3, 5 cm
    f = np.zeros((3, 12))
    f[0, lay.element_at(0, 0)] = 5.0  # a single loaded element: its centre
    f[1, lay.element_at(1, 1)] = 1.0
    f[1, lay.element_at(1, 3)] = 3.0  # weights 1:3 between x = 3 and x = 7 -> x = 6
    xy = centre_of_force(f, lay)
    np.testing.assert_allclose(xy[0], lay.xy_cm[lay.element_at(0, 0)])
    np.testing.assert_allclose(xy[1], [6.0, lay.xy_cm[lay.element_at(1, 1)][1]])
    np.testing.assert_allclose(xy[2], lay.xy_cm.mean(axis=0))  # unloaded: the centre


def test_area_means_split_the_seat_into_equal_rectangles():
    lay = Layout.grid(4, 4, pitch_cm=1.0)
    maps = np.arange(16, dtype=float).reshape(1, 4, 4)
    a4 = area_means(lay.from_grid(maps), lay, 4)
    # top left 2 x 2 block of 0 1 / 4 5 -> 2.5, etc.
    np.testing.assert_allclose(a4[0], [2.5, 4.5, 10.5, 12.5])
    a16 = area_means(lay.from_grid(maps), lay, 16)
    np.testing.assert_allclose(a16[0], np.arange(16))


def test_feature_set_normalises_to_the_mean_pressure_and_names_columns():
    lay = Layout.grid(2, 2, pitch_cm=1.0)
    f = np.array([[1.0, 1.0, 2.0, 4.0]])
    fs = FeatureSet(("elements", "areas4", "back"))
    X = fs.transform(f, lay, back=[0.5])
    assert fs.names(lay) == ["e1", "e2", "e3", "e4", "a1", "a2", "a3", "a4", "back"]
    np.testing.assert_allclose(X[0], [0.5, 0.5, 1.0, 2.0, 0.5, 0.5, 1.0, 2.0, 0.5])
    # the same posture with twice the weight gives the same normalised features
    np.testing.assert_allclose(fs.transform(2 * f, lay, back=[0.5]), X)


def test_alignment_and_pooling():
    maps = np.zeros((1, 8, 8))
    maps[0, 1, 1] = 1.0  # far from the middle
    aligned = align_maps(maps)
    r, c = np.mgrid[:8, :8]
    assert (aligned[0] * r).sum() / aligned[0].sum() == pytest.approx(3.5)
    assert (aligned[0] * c).sum() / aligned[0].sum() == pytest.approx(3.5)
    lay = Layout.grid(8, 8, pitch_cm=1.0)
    fs = FeatureSet(("elements",), normalise=False, pool=4)
    X = fs.transform(lay.from_grid(np.ones((1, 8, 8))), lay)
    assert X.shape == (1, 4) and fs.names(lay) == ["b0_0", "b0_1", "b1_0", "b1_1"]


def test_pooling_a_grid_it_does_not_divide_keeps_the_edge_and_says_so(caplog):
    """--pool 2 on a 30 x 11 grid (the in-bed data set of issue 17) used to stop with an
    error: the last column of blocks now averages the one column there is."""
    lay = Layout.grid(30, 11, pitch_cm=1.0)
    maps = np.arange(330, dtype=float).reshape(1, 30, 11)
    fs = FeatureSet(("elements",), normalise=False, pool=2)
    with caplog.at_level("WARNING", logger="texsense"):
        X = fs.transform(lay.from_grid(maps), lay)
    assert X.shape == (1, 15 * 6) and len(fs.names(lay)) == 90
    grid = X.reshape(15, 6)
    assert grid[0, 0] == np.mean([0, 1, 11, 12])  # a whole block
    assert grid[0, 5] == np.mean([10, 21])  # the edge block: the last column only
    assert "pool 2 on a 30 x 11 grid" in caplog.text and "1 of 2 columns" in caplog.text


def test_feature_set_errors():
    lay = Layout.grid(3, 3, pitch_cm=1.0)
    with pytest.raises(ParameterError, match="feature kinds"):
        FeatureSet(("elements", "colour"))
    with pytest.raises(ParameterError, match="back sensor"):
        FeatureSet(("back",)).transform(np.ones((1, 9)), lay)
    with pytest.raises(ParameterError, match=r"shape \(T, 9\)"):
        FeatureSet().transform(np.ones((1, 4)), lay)
    pts = Layout.points([[0, 0], [1, 0]])
    with pytest.raises(ParameterError, match="grid layout"):
        FeatureSet(("elements",), align=True).transform(np.ones((1, 2)), pts)


class _SubjectSpy(ClassifierMixin, BaseEstimator):
    """Column 0 is the subject id: remembers which subjects it trained on and fails if asked
    to predict one of them."""

    def fit(self, X, y):
        self.seen_ = set(X[:, 0].tolist())
        self.majority_ = np.unique(y)[0]
        return self

    def predict(self, X):
        assert not self.seen_ & set(X[:, 0].tolist()), "a test subject was in the training set"
        return np.full(X.shape[0], self.majority_)


def test_loso_never_trains_on_the_held_out_subject():
    groups = np.repeat(np.arange(5), 6)
    X = np.c_[groups, np.zeros(30)]
    y = np.tile([0, 1], 15)
    report = loso(X, y, groups.astype(str), _SubjectSpy())
    assert sorted(report.per_subject) == ["0", "1", "2", "3", "4"]
    assert report.confusion.sum() == 30
    assert report.accuracy == pytest.approx(0.5)


def test_loso_extra_samples_of_the_held_out_subject_stay_out():
    groups = np.repeat(np.arange(5), 6)
    X = np.c_[groups, np.zeros(30)]
    y = np.tile([0, 1], 15)
    # every subject's extra samples carry its own id: the spy would see it in training
    extra = (np.c_[groups, np.ones(30)], y, groups.astype(str))
    report = loso(X, y, groups.astype(str), _SubjectSpy(), extra=extra)
    assert report.confusion.sum() == 30  # extra samples are never tested
    with pytest.raises(ParameterError, match="features"):
        loso(X, y, groups.astype(str), "lda", extra=(np.zeros((3, 5)), y[:3], groups[:3]))


def test_mirror_frames_reverses_the_columns_and_checks_symmetry():
    lay = Layout.grid(2, 3)
    f = np.arange(12.0).reshape(2, 6)
    m = mirror_frames(f, lay)
    np.testing.assert_array_equal(m[0], [2, 1, 0, 5, 4, 3])
    np.testing.assert_array_equal(mirror_frames(m, lay), f)
    # a checkerboard of even width is not symmetric: a mirrored reading would land on a hole
    board = Layout.grid(2, 4, active=(np.add.outer(np.arange(2), np.arange(4)) % 2 == 0))
    with pytest.raises(ParameterError, match="symmetric"):
        mirror_frames(np.zeros((1, board.n_elements)), board)
    odd = Layout.grid(2, 3, active=(np.add.outer(np.arange(2), np.arange(3)) % 2 == 0))
    g = np.arange(float(odd.n_elements))[None]
    np.testing.assert_array_equal(mirror_frames(mirror_frames(g, odd), odd), g)


def test_mirror_samples_swap_labels_and_skip_those_without_a_partner():
    lay = Layout.grid(1, 2)
    f = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [5.0, 0.0]])
    y = np.array([2, 3, 1, 7])  # 7 has no mirror image
    m, y_m, src = mirror_samples(f, y, lay, {"2": "3", "3": "2", 1: 1})
    np.testing.assert_array_equal(src, [0, 1, 2])
    np.testing.assert_array_equal(y_m, [3, 2, 1])
    assert y_m.dtype == y.dtype
    np.testing.assert_array_equal(m, [[0, 1], [1, 0], [1, 1]])


def test_a_model_trained_on_one_side_recognises_the_other_through_mirroring():
    rng = np.random.default_rng(1)
    lay = Layout.grid(4, 6)
    left = np.zeros((40, 4, 6))
    left[:, 1:3, 0:2] = rng.uniform(1, 2, (40, 1, 1))
    middle = np.zeros((40, 4, 6))
    middle[:, 1:3, 2:4] = rng.uniform(1, 2, (40, 1, 1))
    frames = lay.from_grid(np.concatenate([left, middle]))
    y = np.repeat(["left", "middle"], 40)
    right_side = lay.from_grid(left[:, :, ::-1])
    plain = PostureModel(FeatureSet(("elements",)), lay, "logistic").fit(frames, y)
    assert not np.any(plain.predict(right_side) == "right")  # never saw "right"
    table = {"left": "right", "right": "left", "middle": "middle"}
    mirrored = PostureModel(FeatureSet(("elements",)), lay, "logistic", mirror=table).fit(frames, y)
    assert np.all(mirrored.predict(right_side) == "right")
    assert np.all(mirrored.predict(frames) == y)


def test_loso_reports_per_subject_and_the_worst_one():
    rng = np.random.default_rng(0)
    groups = np.repeat(["a", "b", "c"], 40)
    y = np.tile(np.repeat([0, 1], 20), 3)
    X = (4.0 * y + 0.2 * rng.standard_normal(120))[:, None]
    X[groups == "c"] = rng.standard_normal((40, 1))  # subject c tells nothing
    report = loso(X, y, groups, "lda")
    assert report.per_subject["a"] > 0.9 and report.per_subject["b"] > 0.9
    assert report.minimum[0] == "c"
    with pytest.raises(ParameterError, match="two subjects"):
        loso(X, y, np.zeros(120), "lda")
    with pytest.raises(ParameterError, match="unknown classifier"):
        loso(X, y, groups, "oracle")


def test_forward_selection_finds_the_informative_features():
    rng = np.random.default_rng(3)
    n = 240
    y = rng.integers(0, 4, n)
    groups = np.repeat(np.arange(6), n // 6).astype(str)
    X = rng.standard_normal((n, 8))
    X[:, 5] += 3.0 * (y % 2)  # separates 0/2 from 1/3
    X[:, 2] += 3.0 * (y // 2)  # separates 0/1 from 2/3
    chosen, scores = sequential_forward_selection(X, y, groups, 3, show_progress=False)
    assert set(chosen[:2]) == {2, 5}
    assert scores[1] > 0.85 and scores[0] < 0.6  # one feature tells two classes apart
    with pytest.raises(ParameterError, match="k must lie"):
        sequential_forward_selection(X, y, groups, 9, show_progress=False)


def test_class_distances_match_a_hand_computation():
    # two classes, two samples each, in 2-d; pooled within-class covariance by hand
    X = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 4.0], [2.0, 6.0]])
    y = np.array([0, 0, 1, 1])
    dev = np.array([[-1.0, 0.0], [1.0, 0.0], [-1.0, -1.0], [1.0, 1.0]])
    cov = dev.T @ dev / (4 - 2)
    ridge = 0.05 * np.mean(np.diag(cov))
    prec = np.linalg.inv(cov + ridge * np.eye(2))

    def maha(a, b):
        d = np.asarray(a) - np.asarray(b)
        return np.sqrt(d @ prec @ d)

    d_md, d_ms = class_distances(X, y)
    assert d_md == pytest.approx(maha([1, 0], [1, 5]))  # eq. 6.9: both ordered pairs equal
    d_c0 = maha(X[0], X[1])  # eq. 6.10: (d01 + d10) / (2 * 1)
    d_c1 = maha(X[2], X[3])
    assert d_ms == pytest.approx((d_c0 + d_c1) / 2)  # eq. 6.11


def test_posture_model_round_trip_and_bad_files(tmp_path):
    rng = np.random.default_rng(1)
    lay = Layout.grid(4, 4, pitch_cm=2.0)
    y = np.repeat(["left", "right"], 30)
    frames = rng.random((60, 16))
    frames[y == "left", 0] += 3
    frames[y == "right", 15] += 3
    model = PostureModel(FeatureSet(("elements", "centre")), lay, "lda").fit(frames, y)
    path = model.save(tmp_path / "m.joblib")
    back = PostureModel.load(path)
    np.testing.assert_array_equal(back.predict(frames), model.predict(frames))
    assert back.features == model.features and back.layout.shape == (4, 4)
    assert (back.predict(frames) == y).mean() > 0.95
    bad = tmp_path / "bad.joblib"
    bad.write_text("not a model")
    with pytest.raises(FormatError, match="not a texsense posture model"):
        PostureModel.load(bad)
    import joblib

    joblib.dump({"format": "texsense.posture-model", "version": 99}, bad)
    with pytest.raises(FormatError, match="version 99"):
        PostureModel.load(bad)
    joblib.dump({"format": "something else"}, bad)
    with pytest.raises(FormatError, match="expected format"):
        PostureModel.load(bad)
    with pytest.raises(ParameterError, match="not trained"):
        PostureModel(FeatureSet(), lay).predict(frames)


def test_window_vote_follows_the_majority_of_the_last_seconds():
    from texsense.apps.posture.smoothing import WindowVote, window_vote

    vote = WindowVote(window_s=2.0)
    got = [vote.step(lab, t) for t, lab in enumerate("aabbbba")]
    # t=3: a,b,b in [1,3] -> b; a lone 'a' at t=6 after four 'b' stays 'b'
    assert got == ["a", "a", "a", "b", "b", "b", "b"]
    # a confident frame outweighs two unsure ones; ties go to the most recent label
    vote = WindowVote(window_s=10.0)
    vote.step("x", 0, 0.2)
    vote.step("x", 1, 0.2)
    assert vote.step("y", 2, 0.9) == "y"
    assert WindowVote(10.0).step("p", 0) == "p"
    with pytest.raises(ParameterError, match="must not decrease"):
        vote.step("x", 1.0)
    with pytest.raises(TypeError, match="the time comes second"):
        vote.step(3.0, "x")
    with pytest.raises(ParameterError, match=">= 0 s"):
        WindowVote(-1.0)
    # recorded sequences: the vote restarts at a new subject, never carries over
    out = window_vote([0, 1, 2, 0, 1], ["a", "a", "a", "b", "a"], 5.0, ["s1"] * 3 + ["s2"] * 2)
    assert out.tolist() == ["a", "a", "a", "b", "a"]  # s2 starts afresh; a tie: the latest


class _GroupSpy(_SubjectSpy):
    """Records the subjects it is given: only the training subjects may reach it."""

    def fit(self, X, y, groups=None):
        self.groups_ = set(np.asarray(groups).tolist())
        return super().fit(X, y)

    def predict(self, X):
        held = {str(int(v)) for v in X[:, 0]}
        assert not held & self.groups_, "the held-out subject reached the inner choice"
        return super().predict(X)


def test_loso_passes_the_training_subjects_to_a_classifier_that_takes_them():
    groups = np.repeat(np.arange(5), 6)
    X = np.c_[groups, np.zeros(30)]
    y = np.tile([0, 1], 15)
    report = loso(X, y, groups.astype(str), _GroupSpy())
    assert report.confusion.sum() == 30


def test_auto_chooses_by_subject_and_says_what_it_chose():
    from texsense.apps.posture.evaluate import SubjectSelect, make_classifier

    rng = np.random.default_rng(3)
    y = np.repeat([0, 1, 2], 40)
    groups = np.tile(np.repeat(["a", "b", "c", "d"], 10), 3)
    X = np.c_[y + 0.25 * rng.standard_normal(120), rng.standard_normal((120, 3))]
    chooser = SubjectSelect(candidates=(("naive-bayes", None), ("logistic", 1.0)))
    chooser.fit(X, y, groups=groups)
    assert len(chooser.scores_) == 2 and "inner score" in chooser.choice_
    assert chooser.chosen_ in ("naive-bayes", "logistic C=1")
    assert np.mean(chooser.predict(X) == y) > 0.9 and chooser.predict_proba(X).shape == (120, 3)
    alone = SubjectSelect().fit(X, y)  # no subjects: the first candidate, said so
    assert alone.chosen_ == "logistic C=0.3" and "not chosen" in alone.choice_
    svm = SubjectSelect(candidates=(("linear-svm", 0.01),)).fit(X, y)
    assert not hasattr(svm, "predict_proba")
    calibrated = SubjectSelect(candidates=(("linear-svm", 0.01),), probability=True).fit(X, y)
    assert calibrated.predict_proba(X).shape == (120, 3)
    report = loso(X, y, groups, "auto")
    assert report.accuracy > 0.85
    with pytest.raises(ParameterError, match="auto has no regularisation C"):
        make_classifier("auto", c=1.0)


def test_alignment_ignores_readings_below_zero():
    # compensated maps hold small negative readings; they carry no force (and np.cov refuses
    # negative weights)
    m = np.zeros((1, 9, 9))
    m[0, 2:4, 5:7] = 1.0
    noisy = m.copy()
    noisy[0, 8, 0] = -0.05
    for rotate in (False, True):
        a, b = align_maps(m, rotate=rotate), align_maps(noisy, rotate=rotate)
        assert np.isfinite(b).all()
        np.testing.assert_allclose(np.maximum(a, 0).sum(), np.maximum(b, 0).sum(), rtol=1e-6)


def test_a_calibrated_model_gives_its_own_labels_with_their_confidence():
    """predict_with_confidence of a sigmoid-calibrated SVM computes the probabilities once:
    the same labels as predict, the confidence the highest probability."""
    rng = np.random.default_rng(2)
    lay = Layout.grid(4, 4, pitch_cm=2.0)
    y = np.repeat(["left", "right", "supine"], 30)
    frames = rng.random((90, 16))
    frames[y == "left", 0] += 1.0
    frames[y == "right", 15] += 1.0
    from sklearn.calibration import CalibratedClassifierCV

    from texsense.apps.posture.evaluate import make_classifier

    svm = CalibratedClassifierCV(make_classifier("linear-svm"), ensemble=False)  # as trained
    model = PostureModel(FeatureSet(("elements",)), lay, svm).fit(frames, y)
    test = rng.random((40, 16)) + np.where(rng.random((40, 1)) < 0.5, 0.6, 0.0)
    label, confidence = model.predict_with_confidence(test)
    np.testing.assert_array_equal(label, model.predict(test))
    proba = model.estimator.predict_proba(model.features_of(test))
    np.testing.assert_allclose(confidence, proba.max(axis=1))
