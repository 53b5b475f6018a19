"""Every script of benchmarks/ runs (round 15: step_stages.py had been broken for rounds and no
test ran it): each in a child process at a tiny size, exit 0 and a Markdown table on stdout
with no ``nan`` in it. The numbers are not judged (a smoke test: the sizes are far too small
to mean anything). A script in neither :data:`SMALL` nor :data:`NOT_RUN` fails the test, so
a new benchmark is listed here with its small size or the reason it is not run.

Measured on the 2-core machine: the 14 scripts of :data:`SMALL` take 25 s of wall time one
after the other at a load of 6 (26 s with the test's start); 10 of them took 48 s under a
load of 8 with cold caches (the virtual mats' calibrations, mcu_budget's builds: 17 s of
it). The suite's two workers share them."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"

#: The scripts run, with the options that make them tiny.
SMALL: dict[str, list[str]] = {
    "bench_repair": ["--quick"],
    "batch_outputs": ["--repeat", "1", "--frames", "20"],
    "cli_start": ["--repeat", "1"],
    "frame_door": ["--repeat", "1", "--sizes", "16"],
    "mcu_budget": ["--frames", "10"],
    "muscle_sleeve": ["--sessions", "1", "--minutes", "2"],
    "pipeline_virtual": [],  # (~5 s as it is)
    "preisach_inputs": ["--frames", "20", "--elements", "64", "--repeat", "1"],
    "station_follow_cost": ["--frames", "10", "--rounds", "1"],
    "station_frame_cost": ["--frames", "10", "--rounds", "1"],
    "station_mat_cost": ["--frames", "5", "--repeat", "1"],
    "station_mats_cost": ["--mats", "3", "--frames", "2"],
    "step_ab": [
        str(ROOT / "python/texsense/compensation/pipeline.py"),
        "--rows",
        "4",
        "--pairs",
        "1",
    ],
    "step_builds": [sys.executable, "--pairs", "1", "--rows", "4", "--frames", "20", "--pipeline"],
    "step_sizes": ["--rounds", "1", "--frames", "20"],
    "stocking_wear": [],  # (~2 s as it is)
    "step_stages": ["--frames", "20"],
}

_LONG = "no small size yet: over 15 s at its smallest on this machine"
_SERVERS = "starts Mosquitto/PostgreSQL stations and runs for minutes"

#: The scripts not run, and why.
NOT_RUN: dict[str, str] = {
    "archive_scale": _LONG + " (--quick: a Dask cluster and 2,500-frame recordings)",
    "archive_small": "a Dask cluster of 2 processes over 17 real PMD files: 6-13 s at 1 round",
    "bed_virtual": _LONG,
    "calibration_device": _LONG + " (a virtual device on a pseudo-terminal, the CLI)",
    "clock_cases": "runs the generated cases of tests/faults/test_clock.py (tested there)",
    "param_cases": "runs the cases of tests/faults/test_stage_setattr.py, test_stage_ranges.py",
    "time_cases": "runs the generated cases of tests/faults/test_time_entries.py (tested there)",
    "columns_speed": _LONG + " (a 144,185-row table)",
    "drift_accuracy": _LONG + "; writes docs/img/drift_*.png by default",
    "drift_speed": "--quick: ~25 s, most of it the default hysteresis identification",
    "drift_structure": _LONG,
    "drift_transfer": _LONG,
    "fault_table": "runs tests/faults itself (the suite runs them)",
    "hysteresis_accuracy": _LONG + "; writes docs/img/hyst_*.png by default",
    "hysteresis_generalisation": _LONG,
    "hysteresis_laws": _LONG,
    "hysteresis_sampling": _LONG,
    "hysteresis_speed": _LONG,
    "latency_split": "reads the dumps of station_group_capacity.py --dump",
    "loop_probe": "a probe started inside a member by station_group_capacity.py --probe",
    "monitor_load": "a monitor process, WebSocket viewers and Chromium for --seconds (30)",
    "monitor_posture": _LONG + " (a posture model trained on 9 simulated people)",
    "night_drift": _LONG + " (8-hour simulated nights)",
    "night_gamma": "reads the simulated nights night_drift.py caches",
    "night_oracle": _LONG + " (8-hour simulated nights)",
    "pipeline_repair": _LONG + "; writes docs/img/repair_pmd.png by default",
    "pipeline_speed": _LONG + " (--quick)",
    "playback_memory": _LONG,
    "posture_defaults": _LONG + " (nested leave-one-subject-out)",
    "posture_pmd": _LONG + " (leave-one-subject-out)",
    "posture_seat": _LONG,
    "pytest_cpu": "a pytest plugin and the summary of a run's PYTEST_CPU_OUT files",
    "read_speed": _LONG + " (the PMD tree, 20,024 frames)",
    "report_speed": _LONG,
    "station_failover": _SERVERS,
    "station_group_capacity": _SERVERS,
    "station_load": _SERVERS,
    "takeover_gap": "11 s at --people 1 --stride 50: left out for the time budget",
    "virtual_sensor": "writes docs/img/sim_*.png (no option to write elsewhere); ~5 s",
    "ward_feed_cost": _SERVERS,
    "ward_open": _SERVERS + " (and Chromium)",
}

SCRIPTS = sorted(p.stem for p in BENCHMARKS.glob("*.py") if not p.name.startswith("_"))
#: A Markdown table: a row, then its separator line.
TABLE = re.compile(r"^\|.*\|\n\|[-:| ]+\|$", re.MULTILINE)


def test_every_script_is_listed():
    assert set(SMALL).isdisjoint(NOT_RUN)
    assert sorted([*SMALL, *NOT_RUN]) == SCRIPTS, "list a new benchmark in SMALL or NOT_RUN"


def _tools_for(name: str) -> list[str]:
    """The programs a script needs beyond Python (skipped without them, as tests/test_mcu.py
    is)."""
    return ["qemu-system-arm", "arm-none-eabi-gcc", "gcc"] if name == "mcu_budget" else []


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SMALL))
def test_the_benchmark_runs_at_a_tiny_size(name, tmp_path):
    missing = [t for t in _tools_for(name) if shutil.which(t) is None]
    if missing:
        pytest.skip(f"{name} needs {', '.join(missing)}")
    env = {**os.environ, "TEXSENSE_NO_PROGRESS": "1", "OPENBLAS_NUM_THREADS": "1",
           "MPLBACKEND": "Agg"}  # fmt: skip
    proc = subprocess.run(
        [sys.executable, str(BENCHMARKS / f"{name}.py"), *SMALL[name]],
        capture_output=True, text=True, cwd=tmp_path, env=env, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, f"exit {proc.returncode}:\n{proc.stderr[-3000:]}"
    assert TABLE.search(proc.stdout), f"no table printed:\n{proc.stdout[-2000:]}"
    rows = [line for line in proc.stdout.splitlines() if line.startswith("|")]
    assert not [r for r in rows if re.search(r"\bnan\b", r)], proc.stdout[-2000:]


@pytest.mark.parametrize("other", ["/nonexistent/python", "/bin/echo", "/bin/false"])
def test_step_builds_names_an_other_build_it_cannot_use_in_one_line(other: str) -> None:
    """step_builds.py's argument is another interpreter: one that is missing, prints no
    result or fails is one line naming it, not a traceback."""
    done = subprocess.run(
        [sys.executable, str(BENCHMARKS / "step_builds.py"), other, "--pairs", "1"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode != 0
    assert "Traceback" not in done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("step_builds: ") and other in lines[0]
