"""The conformance battery every reader's test calls (cf. MNE's ``_test_raw_reader``):
``check_reader(path, tmp_path)`` reads a real or generated file and checks

- what every recording must satisfy (``conftest.check_recording``: shapes, times, an exact
  round trip through HDF5, statistics);
- reading in blocks of any length gives exactly the whole recording;
- the file cut at several places mid-line is refused with a message naming it (never read
  as a shorter recording), and with ``accept_truncated`` it is either refused too (a format
  whose layout sits at the end) or read as a prefix of the whole recording with one warning;
- a copy in UTF-16 (text formats) reads as the same recording; an empty file and binary
  garbage under the same name are refused naming the file.
"""

from __future__ import annotations

import codecs
import logging
from pathlib import Path

import numpy as np
import pytest

from conftest import check_recording
from texsense import Recording
from texsense.exceptions import FormatError
from texsense.io import load, open_reader


def same_data(a: Recording, b: Recording, skip_labels: tuple[str, ...] = ()) -> bool:
    """Frames, times, validity, labels (but ``skip_labels``) and layout equal (meta may
    differ: the source)."""
    return (
        np.array_equal(a.frames, b.frames, equal_nan=True)
        and np.array_equal(a.times, b.times)
        and np.array_equal(a.valid, b.valid)
        and a.layout == b.layout
        and (a.quantity, a.unit) == (b.quantity, b.unit)
        and a.labels.keys() == b.labels.keys()
        and all(
            np.array_equal(v, b.labels[k], equal_nan=v.dtype.kind == "f")
            for k, v in a.labels.items()
            if k not in skip_labels
        )
    )


def _beside(folder: Path, path: Path) -> Path:
    """A path for a changed copy of ``path`` in ``folder``, inside a folder of the same name
    as ``path``'s (some formats label frames by it: PMD's subject)."""
    copy = folder / path.parent.name / path.name
    copy.parent.mkdir(parents=True, exist_ok=True)
    return copy


def _blocks_equal_whole(path: Path, rec: Recording, options: dict) -> None:
    for size in sorted({1, 7, max(1, rec.n_frames // 3), rec.n_frames + 5}):
        with open_reader(path, **options) as reader:
            blocks = list(reader.blocks(size))
        assert all(b.n_frames == size for b in blocks[:-1]), size
        assert Recording.concatenate(blocks).equals(rec), f"blocks of {size} differ"


def _cut_points(data: bytes, last: bool) -> list[int]:
    """Byte offsets at 30, 60, 90 % (and, if ``last``, two bytes before the end), moved off
    line ends."""
    points = []
    ends = (0.3, 0.6, 0.9)
    for at in [int(len(data) * share) for share in ends] + ([len(data) - 2] if last else []):
        while (at > 1 and data[at - 1 : at] in (b"\n", b"\r")) or data[at : at + 1] in (b"\r",):
            at -= 1
        points.append(at)
    return points


def _truncations(
    path: Path, rec: Recording, tmp_path: Path, options: dict, caplog, last: bool
) -> None:
    data = path.read_bytes()
    for at in _cut_points(data, last):
        cut = _beside(tmp_path / "cut", path)
        cut.write_bytes(data[:at])
        with pytest.raises(FormatError) as err:
            load(cut, **options)
        assert cut.name in str(err.value), err.value
        caplog.clear()
        try:
            part = load(cut, accept_truncated=True, **options)
        except FormatError as e:  # e.g. the layout is at the end: nothing to read
            assert cut.name in str(e)
            continue
        assert part.n_frames <= rec.n_frames, f"cut at byte {at}"
        # (PMD's "reliable" depends on where a file ends: its last 3 frames are not)
        prefix = rec.select(slice(0, part.n_frames))
        assert same_data(part, prefix, ("reliable",)), f"cut at {at}: not a prefix"
        warned = [r for r in caplog.records if r.levelno == logging.WARNING]
        assert len(warned) == 1 and cut.name in warned[0].getMessage(), warned


def check_reader(
    path: Path, tmp_path: Path, caplog, *, tail_cut_seen: bool = True, **options
) -> Recording:
    """Run the battery on ``path`` (``options`` go to the reader); returns the recording.

    ``tail_cut_seen=False`` for a format whose files may end without a line end and whose
    last line is not a frame (pliance: a cut inside the last number of the geometry table
    cannot be told from a complete file; docs/formats.md says so).
    """
    tmp_path.mkdir(parents=True, exist_ok=True)
    rec = load(path, **options)
    check_recording(rec, tmp_path)
    _blocks_equal_whole(path, rec, options)
    if not path.is_file():
        return rec
    _truncations(path, rec, tmp_path, options, caplog, tail_cut_seen)
    head = path.read_bytes()[:4]
    if not head.startswith(b"\x89HDF"):
        text = path.read_bytes().decode("utf-8-sig", errors="strict")
        utf16 = _beside(tmp_path / "utf16", path)
        utf16.write_bytes(codecs.BOM_UTF16_LE + text.encode("utf-16-le"))
        assert same_data(load(utf16, **options), rec), "UTF-16 copy reads differently"
    for name, content in (("empty", b""), ("garbage", bytes(range(256)) * 64)):
        bad = _beside(tmp_path / name, path)
        bad.write_bytes(content)
        with pytest.raises(FormatError, match=path.name.replace(".", r"\.")):
            load(bad, **options)
    return rec
