"""The corrupted inputs of the file fault battery (tests/faults/test_files.py), made
programmatically from the real exports in ../shared/data and from small synthetic files.

Each :class:`Case` builds its input in a folder of its own and says what ``texsense info``
must do with it. Only plain file edits, h5py and APIs older than the fault battery are used
to build them, so that the battery can be run against an older texsense to show which cases
failed there (docs/reliability.md).
"""

from __future__ import annotations

import codecs
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from conftest import SHARED_DATA

VENDOR = SHARED_DATA / "vendor-formats"
PMD = SHARED_DATA / "pmd" / "experiment-i"
ISCAN = VENDOR / "iscan_test.csv"
FSCAN = VENDOR / "fscan_testL.asf"
XSENSOR = VENDOR / "xsensor_data.csv"
PLIANCE = VENDOR / "pliance_test.asc"

#: the rows of issue 28's table that these cases answer
ROWS = {
    "cut": "an export cut short (XSENSOR half file; Tekscan closed early; PMD/CSV at a line end)",
    "hdf5-length": "an HDF5 whose datasets differ in length",
    "values": "NaN, inf, 1e308, negative readings in vendor files; PMD 1.5 and nan",
    "times": "times that go backwards",
    "malformed": "a folder, binary, UTF-16; a broken HDF5 meta; Rows,1000000000",
    "write": "convert with the disk full (ulimit -f) or killed mid-write",
    "onto-input": "process raw.h5 --calibration mat.json -o raw.h5",
}


@dataclass
class Case:
    """One corrupted input: ``make(folder)`` writes it and returns the path to read."""

    area: str
    name: str
    outcome: str  # "clear error", "read, warned", "invalid readings", "read"
    make: Callable[[Path], Path]
    expect: str = ""  # a phrase the error or warning line must hold
    invalid: int = 0  # invalid readings expected ("invalid readings")
    frames: int | None = None  # frames expected to be read ("read, warned", "read")
    args: tuple[str, ...] = ()  # extra arguments for "texsense info"
    row: str = ""  # the key in ROWS this case answers

    @property
    def id(self) -> str:
        return f"{self.area}: {self.name}"


# ---------------------------------------------------------------------------- edit helpers
def _text(path: Path) -> str:
    return path.read_bytes().decode("utf-8-sig")


def _write(folder: Path, name: str, text: str | bytes) -> Path:
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(text.encode("utf-8") if isinstance(text, str) else text)
    return path


def _cut_bytes(src: Path, share: float, name: str) -> Callable[[Path], Path]:
    """The first ``share`` of the bytes (a cut in the middle of a line)."""

    def make(folder: Path) -> Path:
        data = src.read_bytes()
        at = int(len(data) * share)
        while data[at - 1 : at] in (b"\n", b"\r"):
            at -= 1
        return _write(folder, name, data[:at])

    return make


def _lines(src: Path, edit: Callable[[list[str]], list[str]], name: str, end: str = "\n"):
    def make(folder: Path) -> Path:
        return _write(folder, name, end.join(edit(_text(src).splitlines())) + end)

    return make


def _utf16(src: Path, name: str) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        return _write(folder, name, codecs.BOM_UTF16_LE + _text(src).encode("utf-16-le"))

    return make


def _replace_first(src: Path, old: str, new: str, name: str, after: str = ""):
    """``src`` with the first ``old`` after the first ``after`` replaced by ``new``."""

    def make(folder: Path) -> Path:
        text = _text(src)
        start = text.index(after) if after else 0
        at = text.index(old, start)
        return _write(folder, name, text[:at] + new + text[at + len(old) :])

    return make


# ---------------------------------------------------------------------------- PMD
def _pmd_values(*bad: str) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        lines = (PMD / "S1" / "1.txt").read_text().splitlines()
        tokens = lines[10].split("\t")
        tokens[100 : 100 + len(bad)] = bad
        lines[10] = "\t".join(tokens)
        return _write(folder, "S1/1.txt", "\n".join(lines) + "\n")

    return make


def _pmd_published(edit: Callable[[Path], None]) -> Callable[[Path], Path]:
    """A copy of subject S1 of the published tree with the publisher's SHA256SUMS.txt (as
    a download of it would be), then ``edit`` applied to the S1 folder."""

    def make(folder: Path) -> Path:
        root = folder / "pmd"
        s1 = root / "experiment-i" / "S1"
        shutil.copytree(PMD / "S1", s1)
        sums = (PMD.parent / "SHA256SUMS.txt").read_text().splitlines()
        (root / "SHA256SUMS.txt").write_text(
            "\n".join(s for s in sums if "experiment-i/S1/" in s) + "\n"
        )
        edit(s1)
        return s1

    return make


def _cut_at_line_end(path: Path, keep: int) -> None:
    lines = path.read_bytes().split(b"\n")
    path.write_bytes(b"\n".join(lines[:keep]) + b"\n")


def pmd_cases() -> list[Case]:
    s1 = PMD / "S1" / "1.txt"
    nf = 82  # frames in S1/1.txt
    cases = [
        Case("PMD", f"posture file cut at {p:.0%} of its bytes", "clear error",
             _cut_bytes(s1, p, "S1/1.txt"), "truncated")
        for p in (0.3, 0.6, 0.9)
    ]  # fmt: skip
    cases += [
        Case("PMD", "cut inside the last number", "clear error",
             lambda d: _write(d, "S1/1.txt", s1.read_bytes()[:-4]), "truncated", row="cut"),
        Case("PMD", "cut inside the last number, --accept-truncated", "read, warned",
             lambda d: _write(d, "S1/1.txt", s1.read_bytes()[:-4]), "complete frame",
             frames=nf - 1, args=("--accept-truncated",), row="cut"),
        Case("PMD", "published tree: a file cut at a line end", "clear error",
             _pmd_published(lambda s: _cut_at_line_end(s / "4.txt", 30)),
             "does not match its SHA-256", row="cut"),
        Case("PMD", "published tree: a file cut at a line end, --accept-truncated",
             "read, warned", _pmd_published(lambda s: _cut_at_line_end(s / "4.txt", 30)),
             "does not match", frames=1322 - 69 + 30, args=("--accept-truncated",), row="cut"),
        Case("PMD", "published tree: a posture file missing", "clear error",
             _pmd_published(lambda s: (s / "9.txt").unlink()), "are missing", row="cut"),
        Case("PMD", "published tree: one count changed", "clear error",
             _pmd_published(lambda s: (s / "2.txt").write_bytes(
                 (s / "2.txt").read_bytes().replace(b"\t0\t", b"\t7\t", 1))),
             "does not match its SHA-256"),
        Case("PMD", "a count of 1.5", "invalid readings", _pmd_values("1.5"), invalid=1,
             row="values"),
        Case("PMD", "a count of nan", "invalid readings", _pmd_values("nan"), invalid=1,
             row="values"),
        Case("PMD", "counts NaN, inf, -inf", "invalid readings",
             _pmd_values("NaN", "inf", "-inf"), invalid=3, row="values"),
        Case("PMD", "a count of 1e308", "invalid readings", _pmd_values("1e308"), invalid=1,
             row="values"),
        Case("PMD", "negative counts", "invalid readings", _pmd_values("-3", "-0.5"),
             invalid=2, row="values"),
        Case("PMD", "a count that is no number", "clear error", _pmd_values("zero"),
             "line 11: expected integer counts, found 'zero'"),
        Case("PMD", "a line with 2047 counts", "clear error",
             _lines(s1, lambda ls: [*ls[:5], ls[5].rsplit("\t", 2)[0], *ls[6:]], "S1/1.txt"),
             "line 6: expected 2048"),
        Case("PMD", "an empty line between frames", "clear error",
             _lines(s1, lambda ls: [*ls[:5], "", *ls[5:]], "S1/1.txt"), "line 6: an empty line"),
        Case("PMD", "an empty posture file", "clear error",
             lambda d: _write(d, "S1/1.txt", b""), "empty file"),
        Case("PMD", "a subject folder with an empty posture file", "clear error",
             lambda d: _write(d, "S1/1.txt", b"").parent, "no frames"),
        Case("PMD", "posture file 18.txt in a subject folder", "clear error",
             lambda d: (_write(d, "S1/18.txt", s1.read_bytes()), d / "S1")[1],
             "posture file number must be 1..17"),
        Case("PMD", "subject-info-i.csv is binary", "clear error",
             lambda d: (_write(d, "t/S1/1.txt", s1.read_bytes()),
                        _write(d, "t/subject-info-i.csv", b"\xff\xfe\x00garbage"))[0].parent.parent,
             "subject-info-i.csv"),
        Case("PMD", "a UTF-16 copy", "read", _utf16(s1, "S1/1.txt"), frames=nf),
        Case("PMD", "binary garbage as 1.txt in a subject folder", "clear error",
             lambda d: _write(d, "S1/1.txt", bytes(range(256)) * 40).parent, "binary"),
    ]  # fmt: skip
    return cases


# ---------------------------------------------------------------------------- Tekscan
def _iscan_frames(lines: list[str]) -> list[int]:
    return [i for i, s in enumerate(lines) if s.startswith("Frame ")]


def _closed_early(src: Path, keep: int, name: str) -> Callable[[Path], Path]:
    def edit(ls: list[str]) -> list[str]:
        return [*ls[: _iscan_frames(ls)[keep]], "@@"]

    return _lines(src, edit, name)


def _cells(edits: list[tuple[str, int, int, int]], src: Path = ISCAN) -> Callable:
    """``src`` with (value, frame, row, column) cells replaced."""

    def edit(ls: list[str]) -> list[str]:
        for value, frame, row, col in edits:
            at = _iscan_frames(ls)[frame] + 1 + row
            cells = ls[at].split(",")
            cells[col] = value
            ls[at] = ",".join(cells)
        return ls

    return _lines(src, edit, "cell" + src.suffix)


def _cell(value: str, frame: int = 3, row: int = 5, col: int = 5) -> Callable:
    return _cells([(value, frame, row, col)])


def _iscan_time(frame: int, value: str) -> Callable[[Path], Path]:
    def edit(ls: list[str]) -> list[str]:
        at = _iscan_frames(ls)[frame]
        fields = ls[at].split(",")
        fields[1] = f" {value}"
        ls[at] = ",".join(fields)
        return ls

    return _lines(ISCAN, edit, "time.csv")


def _header(src: Path, key: str, value: str, name: str) -> Callable[[Path], Path]:
    def edit(ls: list[str]) -> list[str]:
        return [f"{key} {value}" if s.split(" ")[0] == key else s for s in ls]

    return _lines(src, edit, name)


def tekscan_cases() -> list[Case]:
    cases = [
        Case("Tekscan", f"I-Scan export closed early after {k} of 309 frames", "clear error",
             _closed_early(ISCAN, k, "early.csv"), f"{309 - k} missing", row="cut")
        for k in (1, 150, 308)
    ]  # fmt: skip
    cases += [
        Case("Tekscan", "F-Scan export closed early after 100 of 205 frames", "clear error",
             _closed_early(FSCAN, 100, "early.asf"), "105 missing", row="cut"),
        Case("Tekscan", "closed early, --accept-truncated", "read, warned",
             _closed_early(ISCAN, 150, "early.csv"), "159 missing", frames=150,
             args=("--accept-truncated",), row="cut"),
        Case("Tekscan", "cut at a line end between frames (no @@)", "clear error",
             _lines(ISCAN, lambda ls: ls[: _iscan_frames(ls)[200]], "cut.csv"),
             "no closing '@@'"),
    ]  # fmt: skip
    cases += [
        Case("Tekscan", f"{src.suffix} cut at {p:.0%} of its bytes", "clear error",
             _cut_bytes(src, p, f"cut{src.suffix}"), "truncated")
        for src in (ISCAN, FSCAN)
        for p in (0.3, 0.6, 0.9)
    ]  # fmt: skip
    cases += [
        Case("Tekscan", "cut at 60 %, --accept-truncated", "read, warned",
             _cut_bytes(ISCAN, 0.6, "cut.csv"), "complete frame", args=("--accept-truncated",),
             row="cut"),
        Case("Tekscan", "header cut before ASCII_DATA", "clear error",
             _lines(ISCAN, lambda ls: ls[:12], "head.csv"), "ASCII_DATA"),
        Case("Tekscan", "ROWS 1000000000", "clear error",
             _header(ISCAN, "ROWS", "1000000000", "rows.csv"), "more than a file of",
             row="malformed"),
        Case("Tekscan", "COLS -3", "clear error", _header(ISCAN, "COLS", "-3", "cols.csv"),
             ">= 1"),
        Case("Tekscan", "ROWS not a number", "clear error",
             _header(ISCAN, "ROWS", "2\u00e98", "rows.csv"), "integers"),
        Case("Tekscan", "END_FRAME not a number", "clear error",
             _header(ISCAN, "END_FRAME", "3x9", "end.csv"), "END_FRAME must be an integer"),
        Case("Tekscan", "more frames than END_FRAME declares", "clear error",
             _header(ISCAN, "END_FRAME", "300", "end.csv"), "frame 301 is beyond END_FRAME 300"),
        Case("Tekscan", "a byte flipped in UNITS", "clear error",
             _header(ISCAN, "UNITS", "r\u00e1w", "units.csv"), "UNITS: unknown unit"),
        Case("Tekscan", "a byte flipped in ROW_SPACING", "clear error",
             _header(ISCAN, "ROW_SPACING", "0.1\u00b27 centimeters", "sp.csv"), "ROW_SPACING"),
        Case("Tekscan", "SECONDS_PER_FRAME not a number", "clear error",
             _header(FSCAN, "SECONDS_PER_FRAME", "0.o32", "spf.asf"), "SECONDS_PER_FRAME"),
        Case("Tekscan", "a cell of nan", "invalid readings", _cell("nan"), invalid=1,
             row="values"),
        Case("Tekscan", "a cell of inf", "invalid readings", _cell("inf"), invalid=1,
             row="values"),
        Case("Tekscan", "a cell of 1e308", "invalid readings", _cell("1e308"), invalid=1,
             row="values"),
        Case("Tekscan", "a negative cell", "invalid readings", _cell("-12"), invalid=1,
             row="values"),
        Case("Tekscan", "F-Scan: a pressure of 1e308 kPa and -1 kPa", "invalid readings",
             _cells([("1e308", 10, 30, 9), ("-1", 10, 30, 10)], FSCAN), invalid=2, row="values"),
        Case("Tekscan", "a cell that is no number", "clear error", _cell("x7"),
             "expected a number or 'B'"),
        Case("Tekscan", "a frame's time goes back", "clear error", _iscan_time(100, "3.5"),
             "goes back from", row="times"),
        Case("Tekscan", "a frame's time is no number", "clear error", _iscan_time(100, "t0"),
             "frame time must be a number"),
        Case("Tekscan", "the 'B' pattern changes", "clear error", _cell("B", 7, 5, 5),
             "pattern differs"),
        Case("Tekscan", "a UTF-16 copy", "read", _utf16(ISCAN, "u.csv"), frames=309),
        Case("Tekscan", "a binary .fsx movie", "clear error",
             lambda d: _write(d, "m.fsx", b"\x00\x01\x02" * 100), "export it as ASCII"),
    ]  # fmt: skip
    return cases


# ---------------------------------------------------------------------------- XSENSOR
def _xs_value(value: str, which: int = 0) -> Callable[[Path], Path]:
    return _replace_first(XSENSOR, "107.87", value, f"v{which}.csv")


def xsensor_cases() -> list[Case]:
    cases = [
        Case("XSENSOR", f"export cut at {p:.0%} of its bytes", "clear error",
             _cut_bytes(XSENSOR, p, "x.csv"), "truncated", row="cut")
        for p in (0.25, 0.5, 0.75, 0.999)
    ]  # fmt: skip
    cases += [
        Case("XSENSOR", "export cut in half, --accept-truncated", "read, warned",
             _cut_bytes(XSENSOR, 0.5, "x.csv"), "50 complete frame", frames=50,
             args=("--accept-truncated",), row="cut"),
        Case("XSENSOR", "Rows,1000000000", "clear error",
             _replace_first(XSENSOR, "Rows,31,", "Rows,1000000000,", "rows.csv"),
             "line 19: Rows,1000000000", row="malformed"),
        Case("XSENSOR", "Columns,-1", "clear error",
             _replace_first(XSENSOR, "Columns,11,", "Columns,-1,", "c.csv"), "Columns,-1"),
        Case("XSENSOR", "Rows not a number", "clear error",
             _replace_first(XSENSOR, "Rows,31,", "Rows,3l,", "r.csv"), "expected an integer"),
        Case("XSENSOR", "Units,stone", "clear error",
             _replace_first(XSENSOR, "Units:,mmHg", "Units:,stone", "u.csv"), "unknown unit"),
        Case("XSENSOR", "a sensel of nan", "invalid readings", _xs_value("nan"), invalid=1,
             row="values"),
        Case("XSENSOR", "a sensel of inf", "invalid readings", _xs_value("inf", 1), invalid=1,
             row="values"),
        Case("XSENSOR", "a sensel of 1e308", "invalid readings", _xs_value("1e308", 2),
             invalid=1, row="values"),
        Case("XSENSOR", "a negative sensel", "invalid readings", _xs_value("-107.87", 3),
             invalid=1, row="values"),
        Case("XSENSOR", "a sensel that is no number", "clear error", _xs_value("1o7.87", 4),
             "expected a number for SENSELS row 2, found '1o7.87'"),
        Case("XSENSOR", "a frame's time goes back", "clear error",
             _replace_first(XSENSOR, "Time, 08:21:", "Time, 08:20:", "t.csv", after="FRAME,1480"),
             "goes back from", row="times"),
        Case("XSENSOR", "a time that is no time", "clear error",
             _replace_first(XSENSOR, "Time, 08:21:", "Time, 8h21:", "t.csv", after="FRAME,1480"),
             "hh:mm:ss.fff"),
        Case("XSENSOR", "a frame in the middle lacks a sensor", "clear error",
             _replace_first(XSENSOR, "SENSOR,HX210.11.31.M11-DFM-RF", "GROUP,HX210", "s.csv",
                            after="FRAME,1500"), "frame 1500 has other SENSOR/GROUP blocks"),
        Case("XSENSOR", "a UTF-16 copy", "read", _utf16(XSENSOR, "u.csv"), frames=101),
    ]  # fmt: skip
    return cases


# ---------------------------------------------------------------------------- pliance
def _pl_value(value: str, line: int = 20, col: int = 50) -> Callable[[Path], Path]:
    def edit(ls: list[str]) -> list[str]:
        tokens = ls[line].split()
        tokens[col] = value
        ls[line] = "   ".join(tokens)
        return ls

    return _lines(PLIANCE, edit, "p.asc")


def pliance_cases() -> list[Case]:
    cases = [
        Case("pliance", f"export cut at {p:.0%} of its bytes", "clear error",
             _cut_bytes(PLIANCE, p, "p.asc"), "not found", row="cut")
        for p in (0.3, 0.6, 0.9)
    ]  # fmt: skip
    cases += [
        Case("pliance", "cut, --accept-truncated (no geometry: nothing to read)", "clear error",
             _cut_bytes(PLIANCE, 0.6, "p.asc"), "not found", args=("--accept-truncated",),
             row="cut"),
        Case("pliance", "a pressure of nan", "invalid readings", _pl_value("nan"), invalid=1,
             row="values"),
        Case("pliance", "a pressure of inf", "invalid readings", _pl_value("inf"), invalid=1,
             row="values"),
        Case("pliance", "a pressure of 1e308", "invalid readings", _pl_value("1e308"),
             invalid=1, row="values"),
        Case("pliance", "a negative pressure", "invalid readings", _pl_value("-2.5"),
             invalid=1, row="values"),
        Case("pliance", "a frame's time goes back", "clear error", _pl_value("1.0", 30, 0),
             "line 31: the time 1 s goes back", row="times"),
        Case("pliance", "a frame row one value short", "clear error",
             _lines(PLIANCE, lambda ls: [*ls[:20], ls[20].rsplit(None, 1)[0], *ls[21:]], "p.asc"),
             "line 21: expected 812 values"),
        Case("pliance", "pressure values in bananas", "clear error",
             _replace_first(PLIANCE, "pressure values in kPa", "pressure values in bananas",
                            "p.asc"), "unknown pressure unit"),
        Case("pliance", "a sensor area of -1", "clear error",
             _replace_first(PLIANCE, "0.5428", "-1.000", "p.asc", after="\narea"),
             "must be positive"),
        Case("pliance", "a UTF-16 copy", "read", _utf16(PLIANCE, "u.asc"), frames=281),
    ]  # fmt: skip
    return cases


# ---------------------------------------------------------------------------- wide CSV
def _wide(rows: list[str], name: str = "w.csv", head: str = "time_s,a,b,c") -> Callable:
    text = "# quantity: pressure\n# unit: kPa\n" + head + "\n" + "\n".join(rows) + "\n"
    return lambda d: _write(d, name, text)


def _written_wide(edit: Callable[[bytes], bytes]) -> Callable[[Path], Path]:
    """The I-Scan export written as a texsense wide CSV, then ``edit``ed."""

    def make(folder: Path) -> Path:
        from texsense.io import load, write_wide_csv

        path = write_wide_csv(load(ISCAN), folder / "w.csv")
        path.write_bytes(edit(path.read_bytes()))
        return path

    return make


def _drop_lines(k: int) -> Callable[[bytes], bytes]:
    return lambda b: b"\n".join(b.split(b"\n")[: -(k + 1)]) + b"\n"


def wide_cases() -> list[Case]:
    good = ["0,1,2,3", "0.5,1,2,3", "1.0,1,2,3"]
    return [
        Case("wide CSV", "texsense file cut at a line end", "clear error",
             _written_wide(_drop_lines(100)), "but the file holds 209", row="cut"),
        Case("wide CSV", "texsense file cut at a line end, --accept-truncated", "read, warned",
             _written_wide(_drop_lines(100)), "100 missing", frames=209,
             args=("--accept-truncated",), row="cut"),
        Case("wide CSV", "texsense file cut in a line", "clear error",
             _written_wide(lambda b: b[: len(b) // 2]), "truncated", row="cut"),
        Case("wide CSV", "texsense file cut inside the last number", "clear error",
             _written_wide(lambda b: b[:-3]), "truncated", row="cut"),
        Case("wide CSV", "'# frames: 1000000000'", "clear error",
             _written_wide(lambda b: b.replace(b"# frames: 309", b"# frames: 1000000000")),
             "999999691 missing", row="malformed"),
        Case("wide CSV", "a broken layout line", "clear error",
             _written_wide(lambda b: b.replace(b'# layout: {"', b"# layout: {")), "bad layout"),
        Case("wide CSV", "a broken meta line", "clear error",
             _written_wide(lambda b: b.replace(b"# meta: {", b"# meta: [")), "bad meta line"),
        Case("wide CSV", "an invalid-column index out of range", "clear error",
             _written_wide(lambda b: b.rstrip(b"\n") + b"9999\n"), "element indices"),
        Case("wide CSV", "foreign file: NaN, inf, 1e308 and a negative pressure",
             "invalid readings", _wide(["0,nan,2,3", "0.5,inf,2,-1", "1.0,1e308,2,3"]),
             invalid=4, row="values"),
        Case("wide CSV", "foreign file: time goes back", "clear error",
             _wide([*good, "0.7,1,2,3"]), "line 7: the time 0.7 s goes back", row="times"),
        Case("wide CSV", "foreign file: a time of nan", "clear error",
             _wide(["0,1,2,3", "nan,1,2,3"]), "line 5", row="times"),
        Case("wide CSV", "foreign file: a row one value short", "clear error",
             _wide([*good, "1.5,1,2"]), "line 7: expected 4"),
        Case("wide CSV", "foreign file without unit", "clear error",
             lambda d: _write(d, "w.csv", "time_s,a\n0,1\n"), "never guessed"),
        Case("wide CSV", "a UTF-16 copy of a texsense file", "read",
             _written_wide(lambda b: codecs.BOM_UTF16_LE + b.decode().encode("utf-16-le")),
             frames=309),
    ]  # fmt: skip


# ---------------------------------------------------------------------------- HDF5
def _h5(edit: Callable[[h5py.File], None], name: str = "r.h5") -> Callable[[Path], Path]:
    """The I-Scan export saved as texsense HDF5, then ``edit``ed with h5py."""

    def make(folder: Path) -> Path:
        from texsense.io import load

        path = load(ISCAN).save(folder / name)
        with h5py.File(path, "a") as f:
            edit(f)
        return path

    return make


def _set(key: str, value: object) -> Callable[[h5py.File], None]:
    return lambda f: f.attrs.__setitem__(key, value)


def _bytes(edit: Callable[[bytes], bytes]) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        path = _h5(lambda f: None)(folder)
        path.write_bytes(edit(path.read_bytes()))
        return path

    return make


def _resize(names: tuple[str, ...], n: int) -> Callable[[h5py.File], None]:
    def edit(f: h5py.File) -> None:
        for name in names:
            f[name].resize(n, axis=0)

    return edit


def hdf5_cases() -> list[Case]:
    def unfinished(f: h5py.File) -> None:
        f.attrs["open"], f.attrs["live"] = 1, 0

    def backwards(f: h5py.File) -> None:
        f["times"][100] = 1.0

    return [
        Case("HDF5", "times dataset 3 long, the others 309", "clear error",
             _h5(_resize(("times",), 3)), "differ in length", row="hdf5-length"),
        Case("HDF5", "frames dataset 100 long, the others 309", "clear error",
             _h5(_resize(("frames",), 100)), "differ in length", row="hdf5-length"),
        Case("HDF5", "a label 3 long", "clear error", _h5(_resize(("labels/frame_number",), 3)),
             "differ in length", row="hdf5-length"),
        Case("HDF5", "datasets of different length, --accept-truncated", "read, warned",
             _h5(_resize(("times",), 3)), "differ in length", frames=3,
             args=("--accept-truncated",), row="hdf5-length"),
        Case("HDF5", "every dataset declares 10^9 frames", "clear error",
             _h5(_resize(("frames", "times", "valid", "labels/frame_number"), 10**9)),
             "holds data for at most", row="malformed"),
        Case("HDF5", "meta attribute is broken JSON", "clear error", _h5(_set("meta", "{nope")),
             "'meta' is not JSON", row="malformed"),
        Case("HDF5", "meta attribute is a JSON list", "clear error", _h5(_set("meta", "[]")),
             "'meta' is not a JSON object", row="malformed"),
        Case("HDF5", "meta attribute is a number", "clear error", _h5(_set("meta", 7)),
             "'meta' is not", row="malformed"),
        Case("HDF5", "unit attribute unknown", "clear error", _h5(_set("unit", "furlong")),
             "unknown unit"),
        Case("HDF5", "quantity attribute unknown", "clear error", _h5(_set("quantity", "heat")),
             "quantity"),
        Case("HDF5", "version 99", "clear error", _h5(_set("version", 99)), "version 99"),
        Case("HDF5", "the valid dataset missing", "clear error",
             _h5(lambda f: f.__delitem__("valid")), "'/valid'"),
        Case("HDF5", "the layout's centres missing", "clear error",
             _h5(lambda f: f.__delitem__("layout/xy_cm")), "/layout is damaged"),
        Case("HDF5", "frames of another element count than the layout", "clear error",
             _h5(lambda f: (f.__delitem__("valid"),
                            f.create_dataset("valid", data=np.ones((309, 3), bool)))),
             "/valid has shape (309, 3)"),
        Case("HDF5", "a one-go write its writer did not finish", "clear error",
             _h5(unfinished), "not finished by its writer", row="write"),
        Case("HDF5", "a one-go write not finished, --accept-truncated", "read, warned",
             _h5(unfinished), "not finished", frames=309, args=("--accept-truncated",)),
        Case("HDF5", "a live recording left open (recorder killed)", "read, warned",
             _h5(lambda f: (_set("open", 1)(f), _set("live", 1)(f))),
             "not closed by its recorder", frames=309),
        Case("HDF5", "a frame's time goes back", "clear error", _h5(backwards),
             "frame 101: the time 1 s goes back", row="times"),
        Case("HDF5", "file cut to half its bytes", "clear error",
             _bytes(lambda b: b[: len(b) // 2]), "not a readable HDF5 file"),
        Case("HDF5", "superblock bytes flipped", "clear error",
             _bytes(lambda b: b[:8] + bytes(x ^ 0xFF for x in b[8:40]) + b[40:]),
             "not a readable HDF5 file"),
        Case("HDF5", "an HDF5 file that is not a recording", "clear error",
             lambda d: (h5py.File(d / "o.h5", "w").close(), d / "o.h5")[1],
             "not a texsense recording"),
    ]  # fmt: skip


# ---------------------------------------------------------------------------- any file
def any_cases() -> list[Case]:
    return [
        Case("any recording", "a folder that is not a PMD tree", "clear error",
             lambda d: (d / "empty").mkdir() or d / "empty", "not a PMD tree"),
        Case("any recording", "a folder named like an HDF5 file", "clear error",
             lambda d: (d / "x.h5").mkdir() or d / "x.h5", "x.h5"),
        Case("any recording", "binary garbage named .csv", "clear error",
             lambda d: _write(d, "g.csv", bytes(range(256)) * 64), "unknown format"),
        Case("any recording", "binary garbage without NUL bytes", "clear error",
             lambda d: _write(d, "g.txt", bytes(range(1, 256)) * 64), "unknown format"),
        Case("any recording", "UTF-16 without a byte-order mark", "clear error",
             lambda d: _write(d, "u.csv", _text(ISCAN).encode("utf-16-le")), "unknown format"),
        Case("any recording", "an empty file", "clear error",
             lambda d: _write(d, "e.csv", b""), "empty file", row="malformed"),
        Case("any recording", "a file that does not exist", "clear error",
             lambda d: d / "absent.h5", "no such file"),
        Case("any recording", "an HDF5 signature then garbage", "clear error",
             lambda d: _write(d, "g.h5", b"\x89HDF\r\n\x1a\n" + bytes(range(256)) * 8),
             "not a readable HDF5 file"),
    ]  # fmt: skip


def all_cases() -> list[Case]:
    """Every case of the reading battery."""
    return (
        pmd_cases() + tekscan_cases() + xsensor_cases() + pliance_cases() + wide_cases()
        + hdf5_cases() + any_cases()
    )  # fmt: skip
