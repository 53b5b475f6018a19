"""The CLI's tables (issue 26): subjects in natural order, a confusion matrix whose columns
stay apart with 3- and 4-digit counts and long class names, ``health`` with row and column."""

import numpy as np
import pytest

from texsense import Layout, Recording
from texsense.cli import main
from texsense.commands._tables import confusion_lines, natural_key
from texsense.io import save


def test_natural_order_and_wide_confusion_columns():
    assert sorted(["S10", "S2", "S1", "S11", "S3"], key=natural_key) == [
        "S1",
        "S2",
        "S3",
        "S10",
        "S11",
    ]
    labels = ["left ankle on right knee, leaning back", "upright", "slouching"]
    lines = confusion_lines(labels, [[1234, 5, 0], [17, 999, 100], [0, 8, 4321]])
    head, *rows, legend = lines
    # every count is its own token: columns never run together
    assert [r.split()[-3:] for r in rows] == [
        ["1234", "5", "0"],
        ["17", "999", "100"],
        ["0", "8", "4321"],
    ]
    assert head.split() == ["c1", "upright", "c3"]  # longer than 8 characters: a code
    assert rows[0].lstrip().startswith("c1 left ankle on right knee")
    assert legend == "classes: c1 = left ankle on right knee, leaning back; c3 = slouching"
    # PMD's posture numbers get their names
    lines = confusion_lines(["1", "2"], [[1, 0], [0, 1]], {"1": "supine", "2": "right"})
    assert lines[1].split()[:2] == ["1", "supine"] and lines[-1] == "classes: 1 = supine; 2 = right"


@pytest.fixture()
def eleven_subjects(tmp_path):
    rng = np.random.default_rng(0)
    lay = Layout.grid(2, 3)
    frames, posture, subject = [], [], []
    for s in range(1, 12):
        for p, col in ((1, 0), (2, 2)):
            for _ in range(60):  # 660 frames per class: 3-digit counts
                m = np.zeros((2, 3))
                m[:, col] = rng.uniform(1, 2)
                frames.append(lay.from_grid(m + rng.uniform(0, 0.05, (2, 3))))
                posture.append(p)
                subject.append(f"S{s}")
    labels = {"posture": np.array(posture), "subject": np.array(subject)}
    rec = Recording(np.array(frames), np.arange(len(frames), dtype=float), lay, labels=labels)
    save(rec, tmp_path / "s.h5")
    return tmp_path / "s.h5"


def test_posture_evaluate_lists_subjects_in_natural_order(eleven_subjects, capsys):
    assert main(["posture", "evaluate", str(eleven_subjects), "--classifier", "lda"]) == 0
    out = capsys.readouterr().out
    order = [line.split()[0] for line in out.splitlines() if line.strip().startswith("S")]
    assert order == [f"S{s}" for s in range(1, 12)], order
    matrix = out.split("confusion (rows true, columns predicted):")[1].strip().splitlines()
    assert [r.split()[1:] for r in matrix[1:3]] == [["660", "0"], ["0", "660"]]


def test_health_lists_row_and_column(tmp_path, capsys):
    lay = Layout.grid(3, 4)
    rng = np.random.default_rng(1)
    c = 10 + rng.uniform(0, 0.5, (50, 12))
    c[:, lay.element_at(2, 1)] = 0.0  # a short: reads 0 pF all the time
    save(Recording(c, np.arange(50.0), lay, "capacitance", "pF"), tmp_path / "raw.h5")
    assert main(["health", str(tmp_path / "raw.h5")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split()[:3] == ["element", "row", "column"]
    dead = [line.split() for line in lines[2:] if "dead" in line]
    assert dead == [["e9", "3", "2", "dead", "1", "100.0%", "0.0", "49.0", "short/break", "50"]]
