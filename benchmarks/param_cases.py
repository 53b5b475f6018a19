"""The generated cases of a stage's parameters that the declared ranges did not hold
(harden15): every stage (and the hysteresis model) x every declared parameter x every value
beyond its range, set after construction (tests/faults/test_stage_setattr.py), and every
declared real parameter and fitted number of a mat's and a linear calibration at degenerate
values inside their ranges (denormals, 1e-300, the ends), run on the mat's sample
(tests/faults/test_stage_ranges.py): how many go wrong, and how.

    .venv/bin/python benchmarks/param_cases.py
    PYTHONPATH=OLD/python .venv/bin/python benchmarks/param_cases.py   # an older texsense

(an older checkout ``OLD``, with the compiled core copied into ``OLD/python/texsense``; the
cases are this checkout's). docs/reliability.md's row "a parameter that breaks a stage"
holds the counts.
"""

from __future__ import annotations

import collections
import logging
import sys
import tempfile
import warnings
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1] / "tests"
sys.path[:0] = [str(TESTS)]

import faults.test_stage_ranges as ranges_tests  # noqa: E402
import faults.test_stage_setattr as setattr_tests  # noqa: E402


def main() -> int:
    logging.disable(logging.WARNING)
    warnings.simplefilter("error")  # an overflow is a case gone wrong, as in the tests
    wrong: collections.Counter[str] = collections.Counter()
    total, examples = 0, []
    for case in setattr_tests._cases("beyond"):
        name, key, value = case.values
        total += 1
        what = setattr_tests.set_beyond(name, key, value)
        if what is not None:
            wrong[f"set after construction: {name}"] += 1
            examples.append(f"{name}.{key} = {value!r}: {what}")
    print(f"set after construction: {sum(wrong.values())} of {total} wrong")
    for k, n in sorted(wrong.items()):
        print(f"  {k}: {n}")
    if examples:
        print("  e.g.", *examples[:3], sep="\n    ")
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "cal").mkdir()
        (Path(tmp) / "files").mkdir()
        cal = ranges_tests.make_calibration(Path(tmp) / "cal")
        files = ranges_tests.make_files(Path(tmp) / "files", cal)
        tried, bad = ranges_tests.degenerate_outcomes(files, Path(tmp))
    print(f"degenerate values in range: {len(bad)} of {tried} wrong", *bad, sep="\n  ")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
