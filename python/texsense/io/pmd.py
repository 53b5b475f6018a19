"""PhysioNet PMD pressure maps (Pouyan et al., IEEE EMBS BHI 2017).

Experiment I: ``experiment-i/S{1..13}/{1..17}.txt``; one frame per line, 2048 tab-separated raw
counts = a 64 x 32 map (row-major), Vista Medical FSA SoftFlex 2048 mat, about 1 Hz. The first
and last 3 frames of each file are known to be unreliable: they get ``reliable = False``.

Labels: ``subject`` ("S1".."S13"), ``posture`` (file number 1..17), ``posture_class``
("supine" / "right" / "left"), ``reliable`` (bool), ``file_frame`` (frame index in its file).

Nothing in a posture file says how many frames it holds, but the published tree carries the
publisher's ``SHA256SUMS.txt``: when it is found above the files, every file read is checked
against it (a file cut at a line end, or changed, is refused or, with ``accept_truncated``,
read and reported) and a posture file it lists under the folder read must be there. Each line
ends with a line end: a last line without one was cut mid-frame. Counts that are not a
number, infinite, negative or not an integer (``1.5``) are invalid readings.
"""

from __future__ import annotations

import csv
import hashlib
import re
from collections import deque
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from texsense._core import parse_row
from texsense._progress import progress
from texsense.data.files import real_path
from texsense.data.layout import Layout
from texsense.exceptions import FormatError
from texsense.io._base import FrameRow, Header, RecordingReader
from texsense.io._registry import Probe
from texsense.io._text import TextLines, is_number, open_binary

__all__ = [
    "MIRROR_CLASS",
    "MIRROR_POSTURE",
    "POSTURES",
    "POSTURE_CLASS",
    "PMDReader",
    "is_pmd_path",
]

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
#: maps (:func:`texsense.apps.posture.features.mirror_samples`). 11 and 12 are the two sides'
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


def _read_subject_info(path: Path) -> dict[str, dict[str, float]]:
    if not path.is_file():
        return {}
    try:
        with path.open(encoding="utf-8-sig") as fh:
            rows = list(csv.DictReader(fh))
        info: dict[str, dict[str, float]] = {}
        for row in rows:
            key = f"S{int(row['Subject-Number'])}"
            info[key] = {k: float(v) for k, v in row.items() if k != "Subject-Number"}
    except (KeyError, ValueError, TypeError, UnicodeDecodeError) as e:
        raise FormatError(
            path, f"expected a CSV with a Subject-Number column and numbers ({e})"
        ) from None
    return info


def _jobs(path: Path) -> tuple[list[tuple[str, Path]], Path | None]:
    """The (subject, posture file) pairs under ``path`` and the subject-info file."""
    if not path.exists():
        raise FormatError(path, "no such file or folder")
    if path.is_file():
        subject = path.parent.name if _SUBJECT.match(path.parent.name) else ""
        jobs = [(subject, path)]
        info = None
    elif _subject_folders(path):
        jobs = [(s.name, f) for s in _subject_folders(path) for f in _posture_files(s)]
        info = path / "subject-info-i.csv"
    elif _posture_files(path):
        subject = path.name if _SUBJECT.match(path.name) else ""
        jobs = [(subject, f) for f in _posture_files(path)]
        info = path.parent / "subject-info-i.csv"
    else:
        raise FormatError(
            path, "not a PMD folder: expected subject folders S1, S2, ... or files 1.txt .. 17.txt"
        )
    for _, f in jobs:
        if not _POSTURE_FILE.match(f.name):
            raise FormatError(f, "expected a PMD posture file named <number>.txt")
        if int(f.stem) not in POSTURES:
            raise FormatError(f, f"posture file number must be 1..17, got {int(f.stem)}")
    return jobs, info


def published_sums(path: Path) -> tuple[Path | None, dict[Path, str]]:
    """The publisher's ``SHA256SUMS.txt`` in ``path``'s folder or up to three folders above,
    as {resolved file: hex digest}."""
    here = real_path(path)
    for folder in [here, *here.parents][:5]:
        sums = folder / "SHA256SUMS.txt"
        if sums.is_file():
            table: dict[Path, str] = {}
            with TextLines(sums) as lines:
                for line in lines:
                    parts = line.text.split(None, 1)
                    if len(parts) == 2 and len(parts[0]) == 64:
                        table[real_path(folder / parts[1].strip().lstrip("*"))] = parts[0].lower()
            return sums, table
    return None, {}


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open_binary(path) as f:  # a regular file only: nothing waits on a FIFO
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


class PMDReader(RecordingReader):
    """Read PMD experiment-I data: one posture file, a subject folder or the whole tree.

    Parameters
    ----------
    path : str or Path
        ``.../S3/7.txt``, ``.../S3`` or ``.../experiment-i``.
    pitch_cm : float
        Sensor pitch in cm (not stated by the dataset; 2.54 cm assumed).
    accept_truncated : bool
        Read files that do not match the publisher's checksums or end mid-line, and a tree
        with posture files missing, up to what is there (with a warning) instead of refusing.

    Returns
    -------
    Recording
        Raw counts (quantity ``"raw"``, unit ``"count"``) on a 64 x 32 grid, files placed back
        to back in time at the nominal 1 s frame period.

    Examples
    --------
    >>> from texsense.io import read_pmd
    >>> rec = read_pmd("../shared/data/pmd/experiment-i/S1")
    >>> rec.layout.shape, sorted(set(rec.labels["posture"].tolist()))[:3]
    ((64, 32), [1, 2, 3])
    """

    format = "pmd"
    what = "PhysioNet PMD text files and folders"
    sniff_order = 60

    @classmethod
    def sniff(cls, probe: Probe) -> bool:
        """A PMD tree or subject folder, or a line of 2048 tab-separated counts (a few
        impossible ones, "nan" or "1.5", are the reader's to judge)."""
        if probe.is_folder:
            return is_pmd_path(probe.path)
        tokens = [t for t in probe.first.split("\t") if t.strip()]
        return len(tokens) == 2048 and sum(t.strip().isdigit() for t in tokens) >= 1024

    non_negative = frozenset({"raw"})

    def __init__(
        self,
        path: str | Path,
        *,
        pitch_cm: float = DEFAULT_PITCH_CM,
        accept_truncated: bool = False,
    ) -> None:
        self.pitch_cm = float(pitch_cm)
        self._cuts: list[str] = []
        super().__init__(path, accept_truncated=accept_truncated)

    def _read_header(self) -> Header:
        self.jobs, info_file = _jobs(self.path)
        self.sums_file, self.sums = published_sums(self.path)
        listed = {
            p for p in self.sums if _POSTURE_FILE.match(p.name) and self._under_read_folder(p)
        }
        missing = sorted(listed - {real_path(f) for _, f in self.jobs})
        if missing and self.path.is_dir():
            names = ", ".join(str(p.relative_to(self.sums_file.parent)) for p in missing[:3])  # type: ignore[union-attr]
            more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
            self._note(
                f"{len(missing)} posture file(s) listed in {self.sums_file} are missing "
                f"({names}{more})"
            )
        meta: dict[str, Any] = {
            "format": "physionet-pmd",
            "source": str(self.path),
            "device": "Vista Medical FSA SoftFlex 2048",
            "dataset": "PhysioNet pmd 1.0.0, experiment I (Pouyan et al., IEEE EMBS BHI 2017)",
            "frame_period_nominal_s": FRAME_PERIOD_S,
            "pitch_cm_assumed": self.pitch_cm,
            "postures": {str(k): v for k, v in POSTURES.items()},
            "mirror": {
                "posture": {str(k): v for k, v in MIRROR_POSTURE.items()},
                "posture_class": MIRROR_CLASS,
            },
            "files": [str(f) for _, f in self.jobs],
        }
        if info_file is not None:
            subject_info = _read_subject_info(info_file)
            if subject_info:
                meta["subject_info"] = subject_info
        return Header(
            Layout.grid(ROWS, COLS, pitch_cm=self.pitch_cm),
            "raw",
            "count",
            meta,
            label_dtypes={
                "subject": str,
                "posture": np.int16,
                "posture_class": str,
                "reliable": bool,
                "file_frame": np.int32,
            },
        )

    def _under_read_folder(self, p: Path) -> bool:
        root = real_path(self.path)
        return self.path.is_dir() and root in p.parents

    def _name(self, f: Path) -> str:
        """A posture file as the message names it: below the folder read, or its name."""
        return str(f.relative_to(self.path)) if self.path.is_dir() else f.name

    def _note(self, message: str) -> None:
        self._cuts.append(message)
        shown = "; ".join(self._cuts[:3])
        more = f"; and {len(self._cuts) - 3} more" if len(self._cuts) > 3 else ""
        self._cut(shown + more)

    def _impossible(self, values: np.ndarray) -> dict[str, np.ndarray]:
        out = super()._impossible(values)
        with np.errstate(invalid="ignore"):
            # (NaN is counted as not a number already: a reading is counted once)
            for a in range(0, len(values), 256):  # in slices: no copy of the whole block
                part = values[a : a + 256]
                if np.any(part != np.floor(part)):
                    out["not an integer count"] = values != np.floor(values)
                    break
        return out

    def _frames(self) -> Iterator[FrameRow]:
        t = 0
        jobs = self.jobs
        for subject, f in progress(jobs, total=len(jobs), desc="reading PMD", unit="file"):
            expected = self.sums.get(real_path(f))
            if expected is not None and _sha256(f) != expected:
                self._note(
                    f"{self._name(f)} does not match its SHA-256 in {self.sums_file} (truncated "
                    "or changed)"
                )
            for values, line, file_frame, reliable in self._file_frames(f):
                labels = {
                    "subject": subject,
                    "posture": int(f.stem),
                    "posture_class": POSTURE_CLASS[int(f.stem)],
                    "reliable": reliable,
                    "file_frame": file_frame,
                }
                yield FrameRow(values, t * FRAME_PERIOD_S, line, labels)
                t += 1

    def _file_frames(self, path: Path) -> Iterator[tuple[np.ndarray, int, int, bool]]:
        """(values, line, index in the file, reliable) per frame; the last UNRELIABLE_EDGE
        frames are held back until the file ends, which makes them unreliable."""
        held: deque[tuple[np.ndarray, int, int]] = deque()
        count = 0
        with TextLines(path) as lines:
            for line in lines.data_lines():
                values = self._parse(path, line)
                if values is None:
                    break
                held.append((values, line.number, count))
                count += 1
                if len(held) > UNRELIABLE_EDGE:
                    v, n, k = held.popleft()
                    yield v, n, k, k >= UNRELIABLE_EDGE
        if count == 0 and self._shortfall is None:
            raise FormatError(
                path, f"no frames; expected lines of {ROWS * COLS} tab-separated counts"
            )
        for v, n, k in held:
            yield v, n, k, False

    def _parse(self, path: Path, line: Any) -> np.ndarray | None:
        """One frame's counts, or None (noted as a cut) for a last line without its end."""
        if not line.ended:
            self._note(
                f"truncated: {self._name(path)} ends in the middle of line {line.number} (a "
                "PMD line ends with a line end)"
            )
            return None
        fast = parse_row(line.text, "\t", ROWS * COLS)  # the well-formed line, in Rust
        if fast is not None:
            return fast
        tokens = line.text.strip().split("\t")
        if len(tokens) != ROWS * COLS:
            raise FormatError(
                path,
                f"expected {ROWS * COLS} tab-separated values (a {ROWS} x {COLS} map), "
                f"found {len(tokens)}",
                line.number,
            )
        try:
            with np.errstate(over="ignore"):  # 1e308: infinite in float32, an invalid reading
                return np.array(tokens, dtype=np.float32)
        except ValueError:
            bad = next(t for t in tokens if not is_number(t))
            raise FormatError(
                path, f"expected integer counts, found {bad!r}", line.number
            ) from None
