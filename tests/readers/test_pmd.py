import numpy as np
import pytest

import texsense
from conftest import check_recording
from texsense.exceptions import FormatError
from texsense.io import read_pmd


@pytest.fixture(scope="module")
def tree(shared_data):
    return shared_data / "pmd" / "experiment-i"


@pytest.fixture(scope="module")
def all_frames(tree):
    return texsense.load(tree)


def test_whole_tree(all_frames, tree):
    rec = all_frames
    assert rec.meta["format"] == "physionet-pmd"
    assert rec.n_frames == 20024
    assert rec.layout.shape == (64, 32)
    assert (rec.quantity, rec.unit) == ("raw", "count")
    assert len(set(rec.labels["subject"])) == 13
    assert sorted(set(rec.labels["posture"].tolist())) == list(range(1, 18))
    assert set(rec.labels["posture_class"]) == {"supine", "right", "left"}
    assert rec.meta["subject_info"]["S3"]["Weight/kg"] == 100.0
    # 13 x 17 files, 3 unreliable frames at each end of each file
    assert (~rec.labels["reliable"]).sum() == 13 * 17 * 6


def test_subject_folder_matches_tree(all_frames, tree, tmp_path):
    s5 = read_pmd(tree / "S5")
    part = all_frames.labels["subject"] == "S5"
    np.testing.assert_array_equal(s5.frames, all_frames.frames[part])
    np.testing.assert_array_equal(s5.labels["posture"], all_frames.labels["posture"][part])
    check_recording(s5, tmp_path)


def test_single_file_and_first_last_frames_flagged(tree):
    rec = read_pmd(tree / "S2" / "7.txt")
    assert set(rec.labels["posture"]) == {7}
    assert set(rec.labels["posture_class"]) == {"left"}
    assert rec.labels["subject"][0] == "S2"
    r = rec.labels["reliable"]
    assert not r[:3].any() and not r[-3:].any() and r[3:-3].all()
    # row-major 64 x 32: the value in line 10, column 70 sits at row 2, col 5 of frame 9
    tokens = (tree / "S2" / "7.txt").read_text().splitlines()[9].split("\t")
    assert rec.maps()[9, 2, 5] == float(tokens[69])


def test_corrupt_files(tmp_path, tree):
    lines = (tree / "S1" / "1.txt").read_text().splitlines()
    folder = tmp_path / "S1"
    folder.mkdir()
    (folder / "1.txt").write_text("\n".join([lines[0], lines[1][:-20], lines[2]]) + "\n")
    with pytest.raises(FormatError, match=r"1\.txt, line 2: expected 2048 tab-separated"):
        read_pmd(folder)
    (folder / "1.txt").write_text(lines[0] + "\n" + lines[1].replace("\t0\t", "\tzero\t", 1) + "\n")
    with pytest.raises(FormatError, match="line 2: expected integer counts, found 'zero'"):
        read_pmd(folder)
    (folder / "1.txt").write_text("")
    with pytest.raises(FormatError, match="no frames"):
        read_pmd(folder)
    (folder / "1.txt").write_text(lines[0] + "\n")
    (folder / "18.txt").write_text(lines[0] + "\n")
    with pytest.raises(FormatError, match=r"posture file number must be 1\.\.17"):
        read_pmd(folder)


def test_not_a_pmd_folder(tmp_path):
    with pytest.raises(FormatError, match="not a PMD folder"):
        read_pmd(tmp_path)
    with pytest.raises(FormatError, match="no such file"):
        read_pmd(tmp_path / "missing")
