"""The generated cases of tests/faults/test_time_entries.py (the entries the readers' time
check did not cover: a column table's ``time_s`` under ``read_columns`` and the hysteresis and
drift fits, ``frames_at``, live frames through the monitor, ``texsense record`` and the
calibration wizard) x the time pathologies: how many go wrong, and how.

    .venv/bin/python benchmarks/time_cases.py
    PYTHONPATH=OLD/python .venv/bin/python benchmarks/time_cases.py   # an older texsense

(an older checkout ``OLD``, with the compiled core copied into ``OLD/python/texsense``; the
cases are this checkout's). docs/reliability.md's row "times at the entries no reader
checked" holds the counts.
"""

from __future__ import annotations

import collections
import logging
import os
import sys
import tempfile
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1] / "tests"
sys.path[:0] = [str(TESTS)]

import faults.test_time_entries as tc  # noqa: E402


def main() -> int:
    logging.disable(logging.WARNING)  # the refusals' own lines
    total, wrong = 0, collections.Counter()
    examples: dict[str, str] = {}
    for entry in tc.ENTRIES:
        for pathology in tc.PATHOLOGIES:
            with tempfile.TemporaryDirectory() as tmp:
                here = os.getcwd()
                os.chdir(tmp)
                try:
                    what = tc.case(entry, pathology, Path(tmp))
                finally:
                    os.chdir(here)
            total += 1
            if what is not None:
                wrong[entry] += 1
                examples.setdefault(entry, f"{pathology}: {what[:150]}")
    print(f"{sum(wrong.values())} of {total} cases wrong")
    for entry in tc.ENTRIES:
        print(f"  {entry}: {wrong[entry]} of {len(tc.PATHOLOGIES)}", end="")
        print(f"  (e.g. {examples[entry]})" if entry in examples else "")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
