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


def _published_copy(tree, tmp_path, subject="S1"):
    """A copy of one subject of the published tree with the publisher's checksums."""
    root = tmp_path / "pmd"
    (root / "experiment-i" / subject).mkdir(parents=True)
    sums = (tree.parent / "SHA256SUMS.txt").read_text().splitlines()
    mine = [s for s in sums if f"experiment-i/{subject}/" in s]
    (root / "SHA256SUMS.txt").write_text("\n".join(mine) + "\n")
    for f in (tree / subject).iterdir():
        (root / "experiment-i" / subject / f.name).write_bytes(f.read_bytes())
    return root / "experiment-i" / subject


def test_published_checksums_catch_a_file_cut_at_a_line_end(tree, tmp_path, caplog):
    folder = _published_copy(tree, tmp_path)
    assert read_pmd(folder).n_frames == read_pmd(tree / "S1").n_frames
    data = (folder / "3.txt").read_bytes()
    lines = data.split(b"\n")
    (folder / "3.txt").write_bytes(b"\n".join(lines[:40]) + b"\n")  # 40 whole lines of 90
    with pytest.raises(FormatError, match=r"3\.txt does not match its SHA-256 .*truncated"):
        read_pmd(folder)
    rec = read_pmd(folder, accept_truncated=True)
    assert (rec.labels["posture"] == 3).sum() == 40
    assert "does not match" in caplog.text
    (folder / "5.txt").unlink()
    with pytest.raises(FormatError, match=r"posture file\(s\) listed in .* are missing"):
        read_pmd(folder)


def test_impossible_counts_are_invalid_readings(tree, tmp_path, caplog):
    lines = (tree / "S1" / "1.txt").read_text().splitlines()
    tokens = lines[5].split("\t")
    for k, bad in enumerate(["1.5", "nan", "-4", "1e308", "inf"]):
        tokens[k] = bad
    lines[5] = "\t".join(tokens)
    path = tmp_path / "1.txt"
    path.write_text("\n".join(lines) + "\n")
    rec = read_pmd(path)
    assert (~rec.valid).sum() == 5 and not rec.valid[5, :5].any()
    assert "5 reading(s) marked invalid" in caplog.text
