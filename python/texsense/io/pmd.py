"""PhysioNet PMD pressure maps (Pouyan et al., IEEE EMBS BHI 2017).

Experiment I: ``experiment-i/S{1..13}/{1..17}.txt``; one frame per line, 2048 tab-separated raw
counts = a 64 x 32 map (row-major), Vista Medical FSA SoftFlex 2048 mat, about 1 Hz. The first
and last 3 frames of each file are known to be unreliable: they get ``reliable = False``.

Labels: ``subject`` ("S1".."S13"), ``posture`` (file number 1..17), ``posture_class``
("supine" / "right" / "left"), ``reliable`` (bool), ``file_frame`` (frame index in its file).
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np

from texsense._progress import progress
from texsense.exceptions import FormatError
from texsense.io._text import read_lines
from texsense.layout import Layout
from texsense.recording import Recording

__all__ = ["MIRROR_CLASS", "MIRROR_POSTURE", "POSTURES", "POSTURE_CLASS", "is_pmd_path", "read_pmd"]

ROWS, COLS = 64, 32
#: Frames at each end of a file that the publishers flag as unreliable.
UNRELIABLE_EDGE = 3
#: Nominal frame period in s (the mat samples at about 1 Hz).
FRAME_PERIOD_S = 1.0
#: Sensor pitch in cm. The dataset does not state it; 1 inch is the FSA bed mats' usual pitch
#: and is an assumption (pass ``pitch_cm`` to override).
DEFAULT_PITCH_CM = 2.54

POSTURES: dict[int, str] = {
    1: "supine",
    2: "right",
    3: "left",
    4: "right, 30° wedge",
    5: "right, 60° wedge",
    6: "left, 30° wedge",
    7: "left, 60° wedge",
    8: "supine variant 8",
    9: "supine variant 9",
    10: "supine variant 10",
    11: "supine variant 11",
    12: "supine variant 12",
    13: "right foetal",
    14: "left foetal",
    15: "supine, bed inclined 30°",
    16: "supine, bed inclined 45°",
    17: "supine, bed inclined 60°",
}
POSTURE_CLASS: dict[int, str] = {
    **dict.fromkeys((1, 8, 9, 10, 11, 12, 15, 16, 17), "supine"),
    **dict.fromkeys((2, 4, 5, 13), "right"),
    **dict.fromkeys((3, 6, 7, 14), "left"),
}

#: The mirror image (left and right swapped) of every posture file, for training on mirrored
#: maps (:func:`texsense.posture.features.mirror_samples`). 11 and 12 are the two sides'
#: knee-up variants. Checked on the data (benchmarks/posture_pmd.py prints it): a classifier
#: trained on the original maps of the other subjects labels the mirrored maps of 15 of the 17
#: files mostly as the file named here; the mirrored 60° wedges (5, 7) go about equally to the
#: other side's 30° and 60° wedges, the mirrored 45° incline (16) to the neighbouring inclines.
MIRROR_POSTURE: dict[int, int] = {
    **{p: p for p in (1, 8, 9, 10, 15, 16, 17)},
    **{2: 3, 3: 2, 4: 6, 6: 4, 5: 7, 7: 5, 11: 12, 12: 11, 13: 14, 14: 13},
}
MIRROR_CLASS: dict[str, str] = {"supine": "supine", "right": "left", "left": "right"}

_SUBJECT = re.compile(r"^S(\d+)$")
_POSTURE_FILE = re.compile(r"^(\d+)\.txt$")


def _posture_files(folder: Path) -> list[Path]:
    files = [p for p in folder.iterdir() if p.is_file() and _POSTURE_FILE.match(p.name)]
    return sorted(files, key=lambda p: int(p.stem))


def _subject_folders(folder: Path) -> list[Path]:
    subs = [p for p in folder.iterdir() if p.is_dir() and _SUBJECT.match(p.name)]
    return sorted(subs, key=lambda p: int(p.name[1:]))


def is_pmd_path(path: Path) -> bool:
    """True if ``path`` looks like a PMD tree, subject folder or posture file."""
    if path.is_dir():
        return bool(_subject_folders(path) or _posture_files(path))
    return False


def _read_pmd_file(path: Path) -> np.ndarray:
    lines = read_lines(path)
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise FormatError(path, f"no frames; expected lines of {ROWS * COLS} tab-separated counts")
    frames = np.empty((len(lines), ROWS * COLS), dtype=np.float32)
    for i, line in enumerate(lines):
        tokens = line.strip().split("\t")
        if len(tokens) != ROWS * COLS:
            raise FormatError(
                path,
                f"expected {ROWS * COLS} tab-separated values (a {ROWS} x {COLS} map), "
                f"found {len(tokens)}",
                i + 1,
            )
        try:
            frames[i] = np.array(tokens, dtype=np.float32)
        except ValueError:
            bad = next(t for t in tokens if not t.strip().lstrip("-").isdigit())
            raise FormatError(path, f"expected integer counts, found {bad!r}", i + 1) from None
        if frames[i].min() < 0:
            raise FormatError(path, "expected raw counts >= 0, found a negative value", i + 1)
    return frames


def _read_subject_info(path: Path) -> dict[str, dict[str, float]]:
    if not path.is_file():
        return {}
    with path.open(encoding="utf-8-sig") as fh:
        rows = list(csv.DictReader(fh))
    info: dict[str, dict[str, float]] = {}
    for row in rows:
        key = f"S{int(row['Subject-Number'])}"
        info[key] = {k: float(v) for k, v in row.items() if k != "Subject-Number"}
    return info


def read_pmd(path: str | Path, *, pitch_cm: float = DEFAULT_PITCH_CM) -> Recording:
    """Read PMD experiment-I data: one posture file, a subject folder or the whole tree.

    Parameters
    ----------
    path : str or Path
        ``.../S3/7.txt``, ``.../S3`` or ``.../experiment-i``.
    pitch_cm : float
        Sensor pitch in cm (not stated by the dataset; 2.54 cm assumed).

    Returns
    -------
    Recording
        Raw counts (quantity ``"raw"``, unit ``"count"``) on a 64 x 32 grid, files placed back
        to back in time at the nominal 1 s frame period.

    Examples
    --------
    >>> rec = read_pmd("../shared/data/pmd/experiment-i/S1")
    >>> rec.layout.shape, sorted(set(rec.labels["posture"].tolist()))[:3]
    ((64, 32), [1, 2, 3])
    """
    path = Path(path)
    if not path.exists():
        raise FormatError(path, "no such file or folder")
    info_file: Path | None = None
    if path.is_file():
        subject = path.parent.name if _SUBJECT.match(path.parent.name) else ""
        jobs = [(subject, path)]
    elif _subject_folders(path):
        jobs = [(s.name, f) for s in _subject_folders(path) for f in _posture_files(s)]
        info_file = path / "subject-info-i.csv"
    elif _posture_files(path):
        subject = path.name if _SUBJECT.match(path.name) else ""
        jobs = [(subject, f) for f in _posture_files(path)]
        info_file = path.parent / "subject-info-i.csv"
    else:
        raise FormatError(
            path, "not a PMD folder: expected subject folders S1, S2, ... or files 1.txt .. 17.txt"
        )
    for _, f in jobs:
        if not _POSTURE_FILE.match(f.name):
            raise FormatError(f, "expected a PMD posture file named <number>.txt")
    parts: list[np.ndarray] = []
    subjects: list[np.ndarray] = []
    postures: list[np.ndarray] = []
    file_frames: list[np.ndarray] = []
    for subject, f in progress(jobs, total=len(jobs), desc="reading PMD", unit="file"):
        frames = _read_pmd_file(f)
        posture = int(f.stem)
        if posture not in POSTURES:
            raise FormatError(f, f"posture file number must be 1..17, got {posture}")
        n = frames.shape[0]
        parts.append(frames)
        subjects.append(np.full(n, subject))
        postures.append(np.full(n, posture, dtype=np.int16))
        file_frames.append(np.arange(n, dtype=np.int32))
    frames = np.concatenate(parts)
    file_frame = np.concatenate(file_frames)
    lengths = np.array([p.shape[0] for p in parts])
    last_index = np.repeat(lengths, lengths) - 1
    reliable = (file_frame >= UNRELIABLE_EDGE) & (file_frame <= last_index - UNRELIABLE_EDGE)
    posture = np.concatenate(postures)
    meta = {
        "format": "physionet-pmd",
        "source": str(path),
        "device": "Vista Medical FSA SoftFlex 2048",
        "dataset": "PhysioNet pmd 1.0.0, experiment I (Pouyan et al., IEEE EMBS BHI 2017)",
        "frame_period_nominal_s": FRAME_PERIOD_S,
        "pitch_cm_assumed": pitch_cm,
        "postures": {str(k): v for k, v in POSTURES.items()},
        "mirror": {
            "posture": {str(k): v for k, v in MIRROR_POSTURE.items()},
            "posture_class": MIRROR_CLASS,
        },
        "files": [str(f) for _, f in jobs],
    }
    if info_file is not None:
        subject_info = _read_subject_info(info_file)
        if subject_info:
            meta["subject_info"] = subject_info
    return Recording(
        frames,
        np.arange(frames.shape[0], dtype=np.float64) * FRAME_PERIOD_S,
        Layout.grid(ROWS, COLS, pitch_cm=pitch_cm),
        quantity="raw",
        unit="count",
        labels={
            "subject": np.concatenate(subjects),
            "posture": posture,
            "posture_class": np.array([POSTURE_CLASS[int(p)] for p in posture]),
            "reliable": reliable,
            "file_frame": file_frame,
        },
        meta=meta,
    )
