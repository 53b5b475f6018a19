"""Where the test suite's CPU goes: a pytest plugin that writes each test's CPU time (its
worker's test thread, and the child processes it waited for), and a summary by module.

Run the suite with it (two workers, as scripts/test.sh does), then summarise:

    PYTHONPATH=benchmarks PYTEST_CPU_OUT=/tmp/cpu OPENBLAS_NUM_THREADS=1 \\
        .venv/bin/python -m pytest -q -p pytest_cpu -n 2 --dist loadgroup
    .venv/bin/python benchmarks/pytest_cpu.py /tmp/cpu [--top 30]

Threads a test starts beside its own (a server in the test process) are not counted; child
processes are counted when they are waited for (a tour page's commands, a station stopped).
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path

import pytest


def _cpu(who: int) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    """Each test's CPU (thread, children) and wall time, a line in ``$PYTEST_CPU_OUT-<worker>``."""
    thread, children = _cpu(resource.RUSAGE_THREAD), _cpu(resource.RUSAGE_CHILDREN)
    wall = time.monotonic()
    yield
    thread = _cpu(resource.RUSAGE_THREAD) - thread
    children = _cpu(resource.RUSAGE_CHILDREN) - children
    out = os.environ.get("PYTEST_CPU_OUT", "pytest-cpu")
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    with open(f"{out}-{worker}.tsv", "a", encoding="utf-8") as f:
        f.write(f"{item.nodeid}\t{thread:.2f}\t{children:.2f}\t{time.monotonic() - wall:.2f}\n")


def main() -> None:
    parser = argparse.ArgumentParser(description="summary of a run with -p pytest_cpu")
    parser.add_argument("prefix", help="the PYTEST_CPU_OUT of the run")
    parser.add_argument("--top", type=int, default=30, help="modules shown (30)")
    args = parser.parse_args()
    cpu: dict[str, float] = defaultdict(float)
    wall: dict[str, float] = defaultdict(float)
    total = 0.0
    for path in Path(args.prefix).parent.glob(Path(args.prefix).name + "-*.tsv"):
        for line in path.read_text(encoding="utf-8").splitlines():
            nodeid, thread, children, seconds = line.split("\t")
            module = nodeid.split("::")[0]
            cpu[module] += float(thread) + float(children)
            wall[module] += float(seconds)
            total += float(thread) + float(children)
    print(f"CPU attributed to tests: {total:.0f} s\n")
    print("| module | CPU s | wall s (summed over its tests) |")
    print("|---|---:|---:|")
    for module in sorted(cpu, key=cpu.__getitem__, reverse=True)[: args.top]:
        print(f"| {module} | {cpu[module]:.1f} | {wall[module]:.1f} |")


if __name__ == "__main__":
    main()
