"""The fault battery (docs/reliability.md): every case records one row (area, case, expected
outcome, what happened). ``python benchmarks/fault_table.py`` runs this folder and prints the
table of rows; in the normal test run the rows are only asserted, not printed.

A case calls ``fault_row(area, case, outcome)`` once it has checked the outcome, with one of
:data:`OUTCOMES` (or a short phrase for a case that fits none of them). A case that fails its
assertion records nothing: the table only lists cases that hold.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

#: the outcomes a case can have, in the words of docs/reliability.md
OUTCOMES = {
    "clear error": "one line naming the file (and line or field), exit 1, no traceback",
    "data kept": "the previous file (or recording) is unchanged, no half-written file is left",
    "read, warned": "what is there is read and the loss is said in one line",
    "invalid readings": "the readings are marked invalid, counted and reported",
    "mat live": "the glitch is counted and logged once; the mat is live again within 2 frames",
    "refused": "the request is refused (HTTP 4xx or a refused MQTT connection)",
    "stopped": "the process stopped within 2 s, cleanly, with its children",
    "said": "one clear line on the console and a visible state on the page",
}

_ROWS: list[dict[str, str]] = []


@pytest.fixture
def fault_row():
    """Record a checked case: ``fault_row("HDF5", "datasets of different length", "clear
    error")``."""

    def record(area: str, case: str, outcome: str, detail: str = "", cases: int = 1) -> None:
        """``cases``: how many generated cases the row stands for (issue 32's families)."""
        _ROWS.append({"area": area, "case": case, "outcome": outcome, "detail": detail,
                      "cases": int(cases)})  # fmt: skip

    return record


def pytest_sessionfinish(session, exitstatus):
    out = os.environ.get("TEXSENSE_FAULT_TABLE")
    if out and _ROWS:
        Path(out).write_text(json.dumps(_ROWS, indent=1), encoding="utf-8")


def run_cli(*args: str, cwd: Path | None = None, timeout: float = 120, env=None, preexec=None):
    """``texsense ARGS`` as a child process: (exit code, stdout, stderr)."""
    proc = subprocess.run(
        [sys.executable, "-m", "texsense.cli", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=timeout,
        env=env,
        preexec_fn=preexec,
    )
    return proc.returncode, proc.stdout, proc.stderr


def assert_clear_error(rc: int, err: str, *names: str) -> str:
    """Exit 1, one line on stderr, no traceback, naming each of ``names``; returns the line."""
    lines = [line for line in err.strip().splitlines() if line.strip()]
    assert rc == 1, f"exit {rc}, stderr:\n{err}"
    assert "Traceback" not in err, err
    assert len(lines) == 1, f"expected one line, got:\n{err}"
    for name in names:
        assert name in lines[0], f"{name!r} not named in: {lines[0]}"
    return lines[0]
