import json

import numpy as np
import pytest

from texsense import Layout, Recording
from texsense.apps.posture import PostureModel
from texsense.cli import main
from texsense.io import save


@pytest.fixture()
def labelled(tmp_path):
    """Four subjects, three 'postures' (a load on the left, the middle or the right of a
    4 x 6 grid), every subject placed a little differently, plus unloaded frames."""
    rng = np.random.default_rng(0)
    lay = Layout.grid(4, 6, pitch_cm=2.0)
    frames, posture, subject, hold = [], [], [], []
    for s in range(4):
        for p, col in ((1, 1), (2, 3), (3, 5)):
            for _ in range(12):
                m = np.zeros((4, 6))
                m[1:3, max(col - 1, 0) : col + 1] = rng.uniform(1, 3)
                m[:, (col + s % 2) % 6] += 0.3
                frames.append(lay.from_grid(m + rng.uniform(0, 0.1, (4, 6))))
                posture.append(p)
                subject.append(f"S{s}")
                hold.append(True)
        frames.append(np.zeros(24))
        posture.append(0)
        subject.append(f"S{s}")
        hold.append(False)
    rec = Recording(
        np.array(frames), np.arange(len(frames), dtype=float), lay,
        labels={"posture": np.array(posture), "subject": np.array(subject), "hold": np.array(hold)},
    )  # fmt: skip
    path = tmp_path / "postures.h5"
    save(rec, path)
    return path


def test_posture_evaluate_prints_loso_and_json(labelled, capsys):
    assert (
        main(["posture", "evaluate", str(labelled), "--where", "hold", "--classifier", "lda"]) == 0
    )
    out = capsys.readouterr().out
    assert "leave-one-subject-out accuracy" in out and "S3" in out and "confusion" in out
    assert main(["posture", "evaluate", str(labelled), "--where", "hold", "--window", "5"]) == 0
    text = capsys.readouterr().out
    assert "a vote over the last 5 s" in text and "per frame" in text
    assert main(["posture", "evaluate", str(labelled), "--drop", "0", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert sorted(report["per_subject"]) == ["S0", "S1", "S2", "S3"]
    assert report["labels"] == ["1", "2", "3"] and report["accuracy"] > 0.9


def test_posture_train_writes_a_model_that_loads(labelled, tmp_path, capsys):
    out = tmp_path / "m.joblib"
    assert main(["posture", "train", str(labelled), "--where", "hold", "-o", str(out)]) == 0
    model = PostureModel.load(out)
    assert model.layout.shape == (4, 6) and sorted(model.classes_.tolist()) == [1, 2, 3]


def test_posture_commands_name_missing_labels(labelled, capsys):
    assert main(["posture", "evaluate", str(labelled), "--label", "mood"]) != 0
    assert "no label 'mood'" in capsys.readouterr().err
    assert main(["posture", "evaluate", str(labelled), "--where", "sleeping"]) != 0
    assert "sleeping" in capsys.readouterr().err


def test_study_writes_report_figure_and_numbers(labelled, tmp_path):
    out = tmp_path / "report"
    assert main(["study", str(labelled), "--where", "hold", "-o", str(out)]) == 0
    numbers = json.loads((out / "numbers.json").read_text())
    assert set(numbers["results"]) == {"noise", "hysteresis", "drift", "failures"}
    noise = numbers["results"]["noise"]
    assert noise[0]["rate"] >= noise[-1]["rate"]  # more noise never helps much
    assert numbers["results"]["failures"][-1]["rate"] <= 0.5  # all elements failed: chance
    page = (out / "report.html").read_text()
    assert "study.png" in page and "<table>" in page
    assert (out / "study.png").stat().st_size > 10_000


def test_mirror_option_trains_on_mirrored_frames_and_checks_its_map(labelled, tmp_path, capsys):
    args = ["posture", "evaluate", str(labelled), "--where", "hold", "--classifier", "lda"]
    assert main([*args, "--mirror", "1:3,2", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["mirror"] == {"1": "3", "3": "1", "2": "2"}
    assert report["confusion"] and sum(map(sum, report["confusion"])) == 144  # tested: originals
    assert main([*args, "--mirror"]) != 0  # this file declares no map
    assert "declares no mirror map for label 'posture'" in capsys.readouterr().err
    assert main([*args, "--mirror", "1:3,1:2"]) != 0
    assert "two mirror images" in capsys.readouterr().err
    out = tmp_path / "m.joblib"
    assert main(["posture", "train", str(labelled), "--where", "hold", "--mirror", "1:3,2",
                 "-o", str(out)]) == 0  # fmt: skip
    assert PostureModel.load(out).mirror == {"1": "3", "3": "1", "2": "2"}


def test_defaults_are_used_without_options_and_named(labelled, tmp_path, capsys):
    from texsense.apps.posture.defaults import DEFAULT_C, DEFAULT_CLASSIFIER, DEFAULT_FEATURES

    assert main(["posture", "evaluate", str(labelled), "--where", "hold"]) == 0
    name = DEFAULT_CLASSIFIER + ("" if DEFAULT_C is None else f" C={DEFAULT_C:g}")
    first = capsys.readouterr().out.splitlines()[0]
    assert first == f"{name} on {DEFAULT_FEATURES.describe()}"
    model_path = tmp_path / "default.joblib"
    assert main(["posture", "train", str(labelled), "--where", "hold", "-o", str(model_path)]) == 0
    model = PostureModel.load(model_path)
    assert model.features == DEFAULT_FEATURES and model.classifier_name.startswith(
        DEFAULT_CLASSIFIER
    )
    # the thesis's classifier brings the thesis's features
    nb = tmp_path / "nb.joblib"
    args = ["posture", "train", str(labelled), "--where", "hold", "--classifier", "naive-bayes"]
    assert main([*args, "-o", str(nb)]) == 0
    assert PostureModel.load(nb).features.kinds == ("elements", "centre", "areas4", "areas16")
    assert not PostureModel.load(nb).features.align
    # any feature option replaces the default set
    capsys.readouterr()
    assert main(["posture", "evaluate", str(labelled), "--where", "hold", "--features", "centre",
                 "--json"]) == 0  # fmt: skip
    assert json.loads(capsys.readouterr().out)["features"]["kinds"] == ["centre"]


def test_c_option_and_its_errors(labelled, capsys):
    base = ["posture", "evaluate", str(labelled), "--where", "hold", "--json"]
    assert main([*base, "--classifier", "linear-svm", "--c", "0.5"]) == 0
    assert json.loads(capsys.readouterr().out)["classifier"] == "linear-svm C=0.5"
    assert main([*base, "--classifier", "naive-bayes", "--c", "0.5"]) != 0
    assert "--c has no effect here: it applies to a classifier with a regularisation C" in (
        capsys.readouterr().err)  # fmt: skip
    with pytest.raises(SystemExit) as stopped:  # the option's declared range (argparse: exit 2)
        main([*base, "--classifier", "logistic", "--c", "0"])
    assert stopped.value.code == 2
    assert "--c: the value must be > 0, got 0" in capsys.readouterr().err


def test_mirror_is_on_by_default_where_the_recording_declares_it(tmp_path, capsys):
    rng = np.random.default_rng(1)
    lay = Layout.grid(4, 4, pitch_cm=2.0)
    frames, side, subject = [], [], []
    for s in range(3):
        for label, col in (("left", 0), ("right", 3), ("middle", 1)):
            for _ in range(6):
                m = np.zeros((4, 4))
                m[:, col] = rng.uniform(1, 2)
                if label == "middle":
                    m[:, 2] = m[:, 1]
                frames.append(lay.from_grid(m))
                side.append(label)
                subject.append(f"S{s}")
    rec = Recording(np.array(frames), np.arange(len(frames), dtype=float), lay,
                    labels={"side": np.array(side), "subject": np.array(subject)},
                    meta={"mirror": {"side": {"left": "right", "right": "left",
                                              "middle": "middle"}}})  # fmt: skip
    path = tmp_path / "declared.h5"
    save(rec, path)
    base = ["posture", "evaluate", str(path), "--label", "side", "--json"]
    assert main(base) == 0
    assert json.loads(capsys.readouterr().out)["mirror"]["left"] == "right"
    assert main([*base, "--no-mirror"]) == 0
    assert json.loads(capsys.readouterr().out)["mirror"] is None
    assert main([*base, "--no-mirror", "--mirror"]) != 0
    assert "contradict" in capsys.readouterr().err
