"""Loading the real hysteresis records in ../shared/data for the benchmarks (read in place)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("TEXSENSE_SHARED_DATA", ROOT.parent / "shared" / "data"))


def elastomer_sawtooth() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random sawtooth on the conductive elastomer rig: time (s), displacement (mm, negative =
    stretch) and force (N) (columns t_P, displacement, force).

    Six samples read a displacement of exactly 0 in the middle of a stretch (the position
    jumps by 3-11 mm for one sample and back); they are dropouts of the position reading and
    are left out.
    """
    data = np.loadtxt(DATA / "elastomer-stretch" / "2_7-5_4Epin_rand_sawtooth.csv", delimiter=",")
    d = data[:, 3]
    before = np.abs(d - np.roll(d, 1))
    after = np.abs(d - np.roll(d, -1))
    dropout = (d == 0.0) & (before > 2.0) & (after > 2.0)
    data = data[~dropout]
    return data[:, 4], data[:, 3], data[:, 5]


def _vhb(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rows = []
    for line in path.read_bytes().decode("latin-1").splitlines():
        fields = [v.strip().strip('"') for v in line.split(",")]
        try:
            rows.append([float(v) for v in fields[:3]])
        except ValueError:
            continue  # the two header lines (names in Chinese, then units) and blank lines
    a = np.asarray(rows)
    return a[:, 0], a[:, 1], a[:, 2]


def vhb_cycle(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One VHB 4910 load-unload cycle: time (s), displacement (mm), force (N)."""
    return _vhb(DATA / "vhb4910" / "loading-unloading" / f"{name}.csv")


def vhb_relaxation(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A VHB 4910 relaxation record: time (s), displacement (mm), force (N)."""
    return _vhb(DATA / "vhb4910" / "relaxation" / f"{name}.csv")


def pmd_reliable() -> tuple:
    """PhysioNet PMD experiment I, the frames its publishers mark reliable: layout, frames
    (float64), posture file number, main class (supine / left / right), subject and the
    frame's index in its file."""
    from texsense.io import read_pmd
    from texsense.io.pmd import POSTURE_CLASS

    rec = read_pmd(DATA / "pmd" / "experiment-i")
    keep = rec.labels["reliable"]
    posture = rec.labels["posture"][keep]
    main = np.array([POSTURE_CLASS[int(p)] for p in posture])
    return (rec.layout, rec.frames[keep].astype(np.float64), posture, main,
            rec.labels["subject"][keep], rec.labels["file_frame"][keep])  # fmt: skip


FORC = DATA / "forc"


def forc_record(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A MicroMag FORC file (``../shared/data/forc``) as one record in measurement order:
    field, moment and the index of the curve of every sample (-1 for the calibration points).

    The file holds blocks separated by blank lines after a header (two format series) that
    ends before the first numeric line: a one-point block is the calibration measurement near
    positive saturation (taken before every curve; it wipes the history out), a longer block
    is one first-order reversal curve, from its reversal field upwards.
    """
    text = (FORC / name).read_bytes().decode("latin-1")
    blocks: list[list[tuple[float, float]]] = [[]]
    for line in text.splitlines():
        fields = line.split(",")
        values = None
        if len(fields) >= 2:
            try:
                values = (float(fields[0]), float(fields[1]))
            except ValueError:
                values = None
        if values is None:
            if blocks[-1]:
                blocks.append([])
            continue
        blocks[-1].append(values)
    u, y, c = [], [], []
    curve = 0
    for b in blocks:
        if not b:
            continue
        a = np.asarray(b)
        u.append(a[:, 0])
        y.append(a[:, 1])
        if len(b) == 1:
            c.append(np.array([-1]))
        else:
            c.append(np.full(len(b), curve))
            curve += 1
    return np.concatenate(u), np.concatenate(y), np.concatenate(c)
