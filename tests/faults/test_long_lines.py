"""Family "a line that costs more than the memory budget" (harden12): every text export is read
a line at a time by ``io._text.TextLines``, whose longest line was a fixed 64 MiB; split into
its fields, a line takes many times its bytes (a 26 MB wide CSV header of 3 million element
names took 540 MB under a budget of 64 MiB). The longest line is now 1/``LINE_COST`` of the
memory budget (``io._text.max_line_bytes``).

The table: every text reader's file x a long line at its start, inside its header and among
its frames, under a 32 MiB budget (1 MiB lines): one line naming the file, and the child's
peak memory within the budget.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from faults._families import batch, one_line, small_recording
from faults._file_cases import FSCAN, ISCAN, PLIANCE, PMD, XSENSOR
from texsense.io import save

BUDGET_KIB = 32 * 1024
#: what the child may grow beyond its warm-up besides the budget (as test_budget.py), KiB
CONSTANT_KIB = 96 * 1024
#: the long line's filler: 900,000 distinct fields (7 MB), as a header of element names
LONG = "".join(f",e{k}" for k in range(900_000))


def _sources(folder: Path) -> dict[str, Path]:
    wide = folder / "wide.csv"
    save(small_recording(20), wide)
    pmd = next(iter(sorted(PMD.glob("S*/1.txt"))), None)
    found = {"wide CSV": wide, "Tekscan I-Scan": ISCAN, "Tekscan F-Scan": FSCAN,
             "XSENSOR": XSENSOR, "pliance": PLIANCE, "PMD": pmd}  # fmt: skip
    return {k: v for k, v in found.items() if v is not None and v.exists()}


def _spoiled(src: Path, folder: Path, where: str) -> Path:
    lines = src.read_bytes().splitlines(keepends=True)
    at = {"first line": 0, "header": min(3, len(lines) - 1), "frames": len(lines) * 2 // 3}[where]
    lines[at] = lines[at].rstrip(b"\r\n") + LONG.encode() + b"\n"
    if src.parent.name.startswith("S"):  # a PMD file keeps its name in a subject's folder
        out = folder / f"{where.replace(' ', '-')}" / src.parent.name / src.name
    else:
        out = folder / f"{where.replace(' ', '-')}-{src.name}"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(b"".join(lines))
    return out


@pytest.mark.slow
def test_a_long_line_is_refused_within_the_budget(tmp_path, fault_row):
    sources = _sources(tmp_path)
    assert len(sources) >= 2, sources
    cases, argvs = [], []
    for reader, src in sources.items():
        for where in ("first line", "header", "frames"):
            path = _spoiled(src, tmp_path, where)
            cases.append((reader, where, path))
            argvs.append(["info", str(path)])
    warm_copy = tmp_path / "warm" / "wide.csv"
    warm_copy.parent.mkdir()
    shutil.copy(sources["wide CSV"], warm_copy)
    results, base_kib, peak_kib = batch(argvs, tmp_path, warm=[["info", str(warm_copy)]],
                                        env={"TEXSENSE_MAX_MEMORY": f"{BUDGET_KIB}K"})  # fmt: skip
    bad = []
    for (reader, where, path), (rc, _out, err) in zip(cases, results, strict=True):
        try:
            one_line(rc, err, path.name)
        except AssertionError as e:
            bad.append(f"{reader}, a long line at its {where}: {str(e)[:200]}")
    grown = peak_kib - base_kib
    print(f"{len(cases) - len(bad)} of {len(cases)} cases held; grew {grown // 1024} MiB")
    assert not bad, "\n".join(bad)
    assert grown <= BUDGET_KIB + CONSTANT_KIB, f"the child grew by {grown} KiB"
    fault_row("declares more", f"{len(sources)} text readers x a 7 MB line at the start, in "
              "the header, among the frames, under a 32 MiB budget", "clear error",
              f"{grown // 1024} MiB over the warm-up", cases=len(cases))  # fmt: skip
