"""The generated cases of tests/faults/test_clock.py (every reader's format x the time
pathologies x the commands that read a recording), each run under a 20 s alarm, so that a run
that goes on counts as wrong instead of stopping the count: how many go wrong, and how.

    .venv/bin/python benchmarks/clock_cases.py
    PYTHONPATH=OLD/python .venv/bin/python benchmarks/clock_cases.py   # an older texsense

(an older checkout ``OLD``, with the compiled core copied into ``OLD/python/texsense``).
docs/reliability.md's row "times on a scale no clock has" holds the counts.
"""

from __future__ import annotations

import collections
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1] / "tests"
sys.path[:0] = [str(TESTS)]

import faults.test_clock as tc  # noqa: E402

#: one child per format: each argv under a 20 s alarm (a run that goes on raises there)
CHILD = r"""
import json, os, signal, sys
sys.path.insert(1, TESTS)
from faults._families import call_main
def alarm(*_):
    raise TimeoutError("ran over 20 s")
signal.signal(signal.SIGALRM, alarm)
out = []
for argv in json.load(sys.stdin):
    signal.alarm(20)
    out.append(call_main(argv))
    signal.alarm(0)
    for made in ("out.h5", "out.png", "out.html"):
        if os.path.exists(made):
            os.unlink(made)
json.dump(out, sys.stdout)
""".replace("TESTS", repr(str(TESTS)))


def main() -> int:
    total, how = 0, collections.Counter()
    with tempfile.TemporaryDirectory() as tmp:
        for fmt in tc.KINDS:
            root = Path(tmp) / fmt
            root.mkdir()
            runs = tc.cases(fmt, root)
            if not runs:
                print(f"{fmt}: holds none of the time pathologies")
                continue
            proc = subprocess.run(
                [sys.executable, "-c", CHILD], input=json.dumps([r[1] for r in runs]),
                capture_output=True, text=True, cwd=root,
                env=dict(os.environ, TEXSENSE_NO_PROGRESS="1"), check=True,
            )  # fmt: skip
            for (what, _, file, refused), (rc, _out, err) in zip(
                runs, json.loads(proc.stdout), strict=True
            ):
                total += 1
                wrong = tc._wrong(file, refused, rc, err)
                if wrong:
                    kind = next((k for k, w in (("went on", "ran over 20 s"),
                                 ("traceback", "Traceback"), ("numpy warning", "Warning"))
                                 if w in err), "not refused" if rc == 0 else "other")  # fmt: skip
                    how[kind] += 1
                    print(f"{what}: {kind}: {wrong.strip().splitlines()[-1][:160]}")
    said = ", ".join(f"{n} {k}" for k, n in how.most_common()) or "none"
    print(f"{sum(how.values())} of {total} runs went wrong ({said})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
