"""Families "an option taken and ignored" and "a hostile option value", over the whole command
line (harden10). The commands and their options are walked from the argparse tree
(:func:`leaves`): a new command or option is covered, or fails here for want of a row.

1. Every option of every command that runs to an end here x the command without it (in this
   process, ``texsense.cli.main``): either the outcome changes (what it prints, a file it
   writes) or the option is refused in one line. The few options that act only on data a
   small fixture does not have are listed in :data:`DATA_DEPENDENT`, with what they act on.
   The commands that serve (``monitor``, ``station``, ``record``, ``calibrate wizard``) do not
   end: each of their options is in a declared rule (:mod:`texsense.commands._applies`, rows in
   test_no_effect.py) or in :data:`SERVED` (it acts wherever the command runs).
2. Every argument that takes a value x hostile values (negative, zero, NaN, huge, empty, a
   folder where a file is wanted, a missing file, the command's input as its output, a name
   with a newline): exit 0, 1 or 2 and never a traceback; exit 1 is one line; an empty value
   is refused (taken, it was the option left out, or the current folder). The commands that
   serve only parse and check their options here (started, they would serve).
3. Hypothesis: command lines of 1-4 options at once, each valid, hostile or another of the
   fixture's files (what one option alone does not show: two that contradict each other).

Figures are not rendered here (matplotlib's layout is most of a plotting command's time):
``Figure.savefig`` writes a digest of what the figure shows (its lines, images, collections,
texts, limits), so that an option that changes a figure still changes the file.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import hashlib
import io
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from matplotlib.figure import Figure

from faults._families import call_main, small_recording, two_postures
from texsense import Layout, Recording
from texsense.cli import COMMANDS, build_parser
from texsense.commands._applies import check_given, rules_of
from texsense.io import save

#: a run of each command that ends here, quickly (the fixture's files, in the run's folder)
BASE = {
    "info": ["info", "rec.h5"],
    "convert": ["convert", "rec.h5", "o.h5"],
    "plot": ["plot", "rec.h5", "-o", "o.png"],
    "simulate": ["simulate", "ramp", "-o", "o.h5"],
    "seat-sessions": ["seat-sessions", "-n", "1", "-o", "ss"],
    "design": ["design"],
    "hysteresis fit": ["hysteresis", "fit", "r.csv", "-o", "m.json", "--method", "thesis",
                       "--grid", "20"],
    "hysteresis apply": ["hysteresis", "apply", "model.json", "r.csv", "-o", "o.csv"],
    "hysteresis validate": ["hysteresis", "validate", "model.json", "r.csv"],
    "hysteresis plot": ["hysteresis", "plot", "model.json", "-o", "o.png"],
    "drift fit": ["drift", "fit", "steps.csv"],
    "calibrate mat": ["calibrate", "mat", "--material", "textile-3mm", "--baseline", "cap.h5",
                      "--uniform", "cap1.h5", "--pressure", "1", "-o", "c.json"],
    "calibrate linear": ["calibrate", "linear", "--like", "cap.h5", "-o", "c.json"],
    "process": ["process", "cap.h5", "--calibration", "mat.json", "-o", "o.h5"],
    "repair": ["repair", "rec.h5", "-o", "o.h5"],
    "health": ["health", "cap.h5"],
    "posture evaluate": ["posture", "evaluate", "post.h5", "--features", "centre"],
    "posture train": ["posture", "train", "post.h5", "-o", "o.joblib", "--features", "centre"],
    "study": ["study", "post.h5", "-o", "st"],
    "stocking report": ["stocking", "report", "stock/strip.h5", "--calibration",
                        "stock/calibration.json"],
    "stocking simulate": ["stocking", "simulate", "--hours", "0.5", "-o", "so"],
    "muscle detect": ["muscle", "detect", "musc/sleeve.h5", "--calibration",
                      "musc/calibration.json"],
    "muscle simulate": ["muscle", "simulate", "--minutes", "1.5", "-o", "mo"],
    "report": ["report", "rec.h5", "-o", "o.html"],
    "export mcu": ["export", "mcu", "mat.json", "-o", "o.bin"],
    "rehash": ["rehash", "model.json"],
}  # fmt: skip
#: more runs of some commands, where options act otherwise (each option is given on each)
ALSO = {
    "health": [["health", "cap.h5", "--json"]],
    "export mcu": [["export", "mcu", "lin.json", "--like", "cap.h5", "-o", "o.c"]],
    "process": [["process", "cap.h5", "--calibration", "lin.json", "-o", "o.csv"]],
    "drift fit": [["drift", "fit", "r.csv", "--history", "model.json"]],
    "posture evaluate": [["posture", "evaluate", "post.h5", "--classifier", "naive-bayes"]],
    "posture train": [["posture", "train", "post.h5", "-o", "o.joblib", "--classifier",
                       "naive-bayes"]],
    "report": [["report", "rec.h5", "-o", "o.html", "--mode", "foot"]],
    "simulate": [["simulate", "steps", "-o", "o.h5"]],
}  # fmt: skip
#: a value of an option that differs from its default, by "COMMAND --option" or "--option"
#: (flags and choices are found: a flag given, the first choice that is not the default)
VALUES = {
    "--unit": "kPa", "--frame": "1", "--accept-truncated": "", "plot --output": "o2.png",
    "convert --format": "wide-csv", "simulate --output": "o2.h5", "--spacer": "textile-3mm",
    "--seed": "3", "--csv": "o.csv", "--sample-hz": "5", "simulate --speed": "20",
    "--max": "5", "--cycles": "2", "--hold": "5", "--levels": "1,2", "--p3": "3",
    "--duration": "5", "--mat": "seat", "--link": "l", "--load": "person", "--truth": "t.h5",
    "--hours": "0.4", "simulate --calibration": "mat.json", "--count": "2",
    "--broker": "mqtt://127.0.0.1:1", "--prefix": "ward", "--beds": "1",
    "--sessions": "2", "--rounds": "3", "--rest-s": "10", "--mat-seed": "3",
    "seat-sessions --output": "ss2",
    "design --thickness-mm": "4", "--electrode-cm": "3", "--target-pf": "3", "--rows": "3",
    "--cols": "3", "--spacing-mm": "9", "--line-distance-mm": "3", "--update-hz": "2",
    "--converters": "2",
    "--output-model": "m2.json", "hysteresis fit --input": "capacitance_pF",
    "hysteresis fit --output": "capacitance_pF", "hysteresis fit --grid": "10",
    "--cells": "8", "--smoothing": "0.1", "--folds": "3", "hysteresis fit --drift": "steps.csv",
    "--held-out": "r.csv", "--drift-rest-rate": "0.5",
    "hysteresis apply --input": "capacitance_pF", "hysteresis apply --output": "capacitance_pF",
    "hysteresis apply --interval": "0.9", "hysteresis validate --input": "capacitance_pF",
    "hysteresis validate --output": "capacitance_pF", "--plot": "p.png", "--out": "o2.png",
    "hysteresis apply --out": "o2.csv",
    "--history": "model.json", "drift fit --output": "d.json", "--rest-rate": "0.5",
    "drift fit --clock": "time",
    "calibrate mat --material": "textile-6mm", "--baseline": "cap1.h5", "--uniform": "cap2.h5",
    "--pressure": "2", "calibrate mat --thickness-mm": "3.5", "calibrate mat --drift":
    "steps.csv", "calibrate mat --output": "c2.json", "--orientation": "bed",
    "--replace": "", "calibrate linear --like": "rec.h5", "--offset": "1", "--gain": "2",
    "--to": "pressure:kPa", "--full-scale": "100", "calibrate linear --output": "c2.json",
    "process --calibration": "lin.json", "process --output": "o2.h5",
    "process --interval": "0.9", "--chunk-frames": "2", "--scheduler": "tcp://127.0.0.1:1",
    "--workers": "2", "repair --output": "o2.h5", "health --calibration": "lin.json",
    "--label": "subject", "--where": "seated", "--drop": "a", "--every": "3",
    "posture evaluate --group": "posture", "--window": "2", "--c": "2", "--features": "elements",
    "--back-label": "back", "--pool": "2", "--mirror": "a:b", "posture train --output":
    "o2.joblib", "posture train --group": "subject", "study --output": "st2", "--range": "3",
    "study --pool": "2",
    "stocking report --calibration": "lin.json", "stocking report --every": "0.1",
    "stocking simulate --hours": "0.4", "stocking simulate --output": "so2",
    "muscle detect --calibration": "lin.json", "muscle detect --threshold": "0.3",
    "--minutes": "1", "muscle simulate --output": "mo2",
    "report --output": "o2.html", "report --unit": "mmHg", "--scale": "0,5",
    "report --threshold": "40", "--reposition-min": "30", "--turn-every": "60",
    "report --model": "post.joblib", "--rois": "rois.json",
    "export mcu --output": "o2.bin", "--capacity": "8", "export mcu --like": "cap.h5",
    "--name": "mat",
}  # fmt: skip
#: options whose effect needs data the fixture does not have: what they act on
DATA_DEPENDENT = {
    "--accept-truncated": "a recording cut short (tests/faults/test_files.py)",
    "health --calibration": "an element outside the calibration's expected range",
    "posture evaluate --where": "a boolean label false somewhere (the fixture's is all true)",
    "posture train --where": "a boolean label false somewhere",
    "study --where": "a boolean label false somewhere",
    "--replace": "an output that exists (tests/faults/test_calibrate.py)",
}
#: the commands that serve, and their options that act wherever they run (the others have a
#: declared rule)
SERVED = {
    "monitor": {"--source", "--orientation", "--calibration", "--model", "--bed", "--mode",
                "--record", "--record-dir", "--db", "--host", "--port", "--token",
                "--token-file", "--allow-host", "--allow-origin", "--threshold",
                "--threshold-unit", "--reposition-min", "--offload-min"},
    "station": {"--virtual-mats", "--config", "--broker", "--stale-after", "--refuse-after",
                "--mats", "--reposition-min", "--db", "--record-dir", "--group",
                "--host", "--port", "--token", "--token-file", "--allow-host",
                "--allow-origin"},
    "record": {"--source", "--orientation", "--output", "--duration", "--frames"},
    "calibrate wizard": {"--source", "--orientation", "--output", "--material",
                         "--thickness-mm", "--pressure", "--no-check", "--frames", "--wait-s",
                         "--yes", "--replace"},
}  # fmt: skip
#: hostile values of an argument that takes a number, a path (INPUT: the command's own input
#: file) or a text (all of them)
NUMBERS = ["-1", "0", "nan", "1e308", ""]
PATHS = ["", ".", "missing.h5", "INPUT", "a\nb\x1ec.h5", "a\x00b"]
HOSTILE = NUMBERS[:-1] + PATHS


@functools.cache
def leaves() -> dict[str, argparse.ArgumentParser]:
    """Every command that runs (``"hysteresis fit"``) -> its parser."""
    out: dict[str, argparse.ArgumentParser] = {}

    def walk(p: argparse.ArgumentParser, words: list[str]) -> None:
        subs = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        for action in subs:
            for name, sp in action.choices.items():
                walk(sp, [*words, name])
        if not subs:
            out[" ".join(words)] = p

    walk(build_parser(COMMANDS), [])
    return out


def _options(p: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in p._actions if a.option_strings and a.dest != "help"]


def _value(command: str, action: argparse.Action) -> str | None:
    """A value for ``action`` other than its default ("" for a flag), None if none known."""
    flag = action.option_strings[-1]
    for key in (f"{command} {flag}", flag):
        if key in VALUES:
            return VALUES[key]
    if action.nargs == 0:
        return ""
    if action.choices:
        return next(str(c) for c in action.choices if c != action.default)
    return None


def _with(base: list[str], action: argparse.Action, value: str) -> list[str]:
    """``base`` with ``action`` given ``value`` (replacing the value it has there)."""
    argv = list(base)
    named = [k for k, a in enumerate(argv) if a in action.option_strings]
    if named:
        if action.nargs == 0:
            return argv
        argv[named[0] + 1] = value
        return argv
    return [*argv, action.option_strings[-1], *([] if action.nargs == 0 else [value])]


def _digest(fig: Figure) -> bytes:
    """What a figure shows, without drawing it."""
    h = hashlib.sha1()
    for ax in fig.axes:
        h.update(repr((ax.get_title(), ax.get_xlabel(), ax.get_ylabel(), ax.get_xlim(),
                       ax.get_ylim())).encode())  # fmt: skip
        for artist in [*ax.lines, *ax.images, *ax.collections, *ax.patches, *ax.texts]:
            for name in ("get_xydata", "get_array", "get_offsets", "get_text", "get_xy"):
                value = getattr(artist, name, lambda: None)()
                h.update(repr(np.asarray(value, dtype=object).tolist()).encode())
    for text in fig.texts:
        h.update(text.get_text().encode())
    return h.hexdigest().encode()


@pytest.fixture(autouse=True)
def undrawn_figures(monkeypatch):
    """``Figure.savefig`` writes :func:`_digest` (to a file or a buffer)."""

    def savefig(fig: Figure, fname, **_kw) -> None:
        if hasattr(fname, "write"):
            fname.write(_digest(fig))
        else:
            Path(fname).write_bytes(_digest(fig))

    monkeypatch.setattr(Figure, "savefig", savefig)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """The files the base runs read."""
    root = tmp_path_factory.mktemp("every-option")
    save(small_recording(), root / "rec.h5")
    save(two_postures(), root / "post.h5")
    for name, level in (("cap.h5", 10.0), ("cap1.h5", 12.0), ("cap2.h5", 13.0)):
        values = level + 0.01 * np.random.default_rng(int(level)).standard_normal((6, 12))
        save(Recording(values, np.arange(6.0), Layout.grid(3, 4), "capacitance", "pF"),
             root / name)  # fmt: skip
    (root / "rois.json").write_text(json.dumps({"regions": [
        {"name": "r", "kind": "box", "points": [[0, 0], [2, 2]]}]}))  # fmt: skip
    made = [
        ["calibrate", "linear", "--like", "cap.h5", "--gain", "2", "-o", "lin.json"],
        ["calibrate", "mat", "--material", "textile-3mm", "--baseline", "cap.h5", "--uniform",
         "cap1.h5", "--pressure", "1", "-o", "mat.json"],
        ["simulate", "calibration", "--csv", "r.csv"],
        ["simulate", "steps", "--levels", "1,2", "--hold", "60", "--csv", "steps.csv"],
        ["hysteresis", "fit", "r.csv", "-o", "model.json", "--method", "thesis", "--grid", "20"],
        ["posture", "train", "post.h5", "-o", "post.joblib", "--features", "centre"],
        ["muscle", "simulate", "--minutes", "1.5", "-o", "musc"],
        ["stocking", "simulate", "--hours", "0.5", "-o", "stock"],
    ]  # fmt: skip
    with contextlib.chdir(root):
        for argv in made:
            assert call_main(argv)[0] == 0, argv
    return root


def _outcome(folder: Path, fixed: set[str], result: tuple[int, str, str]) -> tuple:
    """What a run did: exit code, what it printed (times left out), the files it wrote."""
    files = {}
    for f in sorted(folder.rglob("*")):
        if f.is_file() and str(f.relative_to(folder)) not in fixed:
            files[str(f.relative_to(folder))] = hashlib.sha1(f.read_bytes()).hexdigest()
    rc, out, _ = result
    return rc, re.sub(r"\d+\.\d+ s\)", "T s)", out), files


def _clean(folder: Path, fixed: set[str]) -> None:
    for f in list(folder.iterdir()):
        if f.name not in fixed:
            shutil.rmtree(f) if f.is_dir() else f.unlink()


def _one_line_or_usage(rc: int, err: str) -> str | None:
    """What is wrong with a run's failure: a traceback, an exit other than 0, 1, 2, or more
    than one line for exit 1; None if nothing."""
    lines = [
        line
        for line in err.strip().splitlines()
        if line.strip() and not line.startswith("  failed: ")
    ]  # (an archive's files)
    if "Traceback" in err or rc not in (0, 1, 2):
        return f"exit {rc}: {err[-600:]}"
    if rc == 1 and len(lines) != 1:
        return f"exit 1 in {len(lines)} lines: {err[-600:]}"
    return None


def test_every_command_is_a_base_run_or_serves():
    missing = sorted(set(leaves()) - set(BASE) - set(SERVED))
    assert missing == [], f"give these commands a BASE run (or SERVED options): {missing}"


def test_every_option_of_a_served_command_has_a_rule_or_always_acts():
    wrong = []
    for command, flags in SERVED.items():
        p = leaves()[command]
        ruled = {r.flag for r in rules_of(p)}
        for action in _options(p):
            if not set(action.option_strings) & (ruled | flags):
                wrong.append(f"{command} {action.option_strings[-1]}")
    assert wrong == [], f"options with neither a rule nor a place in SERVED: {wrong}"


@pytest.mark.parametrize("command", sorted(BASE))
def test_every_option_acts_or_is_refused(command, inputs, fault_row):
    fixed = {str(f.relative_to(inputs)) for f in inputs.rglob("*")}
    p = leaves()[command]
    wrong, counted = [], 0
    with contextlib.chdir(inputs):
        for base_argv in [BASE[command], *ALSO.get(command, [])]:
            _clean(inputs, fixed)
            base = call_main(base_argv)
            assert base[0] == 0, (base_argv, base)
            before = _outcome(inputs, fixed, base)
            for action in _options(p):
                flag = action.option_strings[-1]
                value = _value(command, action)
                assert value is not None, f"give {command} {flag} a value in VALUES"
                argv = _with(base_argv, action, value)
                if argv == base_argv or flag == "--scheduler":  # (the base gives it; a dial)
                    continue
                _clean(inputs, fixed)
                result = call_main(argv)
                counted += 1
                problem = _one_line_or_usage(result[0], result[2])
                if problem:
                    wrong.append(f"{' '.join(argv)}: {problem}")
                elif (result[0] == 0 and _outcome(inputs, fixed, result) == before
                      and not {f"{command} {flag}", flag} & set(DATA_DEPENDENT)):  # fmt: skip
                    wrong.append(f"{' '.join(argv)}: taken and ignored (same outcome)")
        _clean(inputs, fixed)
    assert wrong == [], "\n".join(wrong)
    fault_row("no effect", f"{command}: each of its options, with and without it",
              "acts or refused", cases=counted)  # fmt: skip


def _valued(p: argparse.ArgumentParser) -> list[argparse.Action]:
    """The arguments that take a value (positionals included)."""
    return [a for a in p._actions if a.nargs != 0 and a.dest != "help"
            and not isinstance(a, argparse._SubParsersAction)]  # fmt: skip


def _hostile(action: argparse.Action) -> list[str]:
    """The hostile values for an argument: by what it takes."""
    if action.type is not None and getattr(action.type, "__name__", "") == "path":
        return PATHS
    if hasattr(action.type, "allowed"):  # a number with its declared range
        return NUMBERS
    return HOSTILE


def _hostile_argv(command: str, p: argparse.ArgumentParser, action: argparse.Action,
                  value: str) -> list[str]:  # fmt: skip
    """The base run with ``action`` given a hostile ``value``."""
    base = BASE[command]
    args = p.parse_args(base[len(command.split()) :])
    first = next((v for v in vars(args).values() if isinstance(v, Path)), Path("rec.h5"))
    value = str(first) if value == "INPUT" else value
    if action.option_strings:
        return _with(base, action, value)
    given = getattr(args, action.dest)
    given = given[0] if isinstance(given, list) else given
    k = base.index(str(given), len(command.split()))
    return [*base[:k], value, *base[k + 1 :]]


@pytest.mark.parametrize("command", sorted(BASE))
def test_hostile_values_never_a_traceback(command, inputs, fault_row):
    fixed = {str(f.relative_to(inputs)) for f in inputs.rglob("*")}
    p = leaves()[command]
    wrong, counted = [], 0
    with contextlib.chdir(inputs):
        for action in _valued(p):
            if action.dest == "scheduler":
                continue  # (an address: a hostile one waits for its time-out)
            for value in _hostile(action):
                argv = _hostile_argv(command, p, action, value)
                _clean(inputs, fixed)
                rc, _out, err = call_main(argv)
                counted += 1
                problem = _one_line_or_usage(rc, err)
                if value == "" and rc == 0:  # an empty word is never the option left out
                    problem = "an empty value taken (as if the option were left out)"
                if problem:
                    wrong.append(f"{' '.join(argv)!r}: {problem}")
        _clean(inputs, fixed)
    assert wrong == [], f"{len(wrong)} of {counted}:\n" + "\n".join(wrong)
    fault_row("hostile value", f"{command}: every argument x its hostile values "
              "(a number: negative, 0, NaN, huge, empty; a path: empty, a folder, missing, the "
              "input; a text: all)", "no traceback", "exit 0, 2, or 1 in one line",
              cases=counted)  # fmt: skip


@pytest.mark.parametrize("command", sorted(SERVED))
def test_hostile_values_of_a_served_command_are_checked_before_it_serves(command):
    """Parsed and checked only (started, the command would serve)."""
    p = leaves()[command]
    parser = build_parser(COMMANDS)
    words = command.split()
    wrong = []
    for action in _valued(p):
        for value in _hostile(action):
            argv = [*words, action.option_strings[-1], value]
            err = io.StringIO()
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                try:
                    args = parser.parse_args(argv)
                    check_given(parser, args, argv)
                except SystemExit as e:
                    if e.code != 2:
                        wrong.append(f"{argv}: exit {e.code}")
                except Exception as e:
                    if type(e).__name__ != "ParameterError":
                        wrong.append(f"{argv}: {type(e).__name__}: {e}")
    assert wrong == [], "\n".join(wrong)


#: commands whose run time grows with a value (hours, minutes, sessions): not drawn in 3.
_LONG = {"seat-sessions", "stocking simulate", "muscle simulate", "simulate"}


@st.composite
def command_lines(draw, files: list[str]) -> list[str]:
    """A base run with 1-4 of its options, each given a valid, hostile or file value."""
    command = draw(st.sampled_from(sorted(set(BASE) - _LONG)))
    argv = list(draw(st.sampled_from([BASE[command], *ALSO.get(command, [])])))
    actions = [a for a in _options(leaves()[command]) if a.dest != "scheduler"]
    if not actions:
        return argv
    for action in draw(st.lists(st.sampled_from(actions), min_size=1, max_size=4,
                                unique_by=id)):  # fmt: skip
        valid = _value(command, action)
        choices = [str(c) for c in action.choices or []]
        value = draw(st.sampled_from([*HOSTILE, *files, *choices,
                                      *([] if valid is None else [valid])]))  # fmt: skip
        argv = _with(argv, action, "" if action.nargs == 0 else value)
    return argv


def test_command_lines_of_several_options_never_a_traceback(inputs, fault_row):
    fixed = {str(f.relative_to(inputs)) for f in inputs.rglob("*")}
    files = sorted(f for f in fixed if "." in f)
    tried: list[str] = []

    @settings(max_examples=120, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))  # fmt: skip
    @given(command_lines(files))
    def run(argv: list[str]) -> None:
        _clean(inputs, fixed)
        rc, _out, err = call_main(argv)
        tried.append(" ".join(argv))
        problem = _one_line_or_usage(rc, err)
        assert problem is None, f"{argv!r}: {problem}"

    with contextlib.chdir(inputs):
        try:
            run()
        finally:
            _clean(inputs, fixed)
    fault_row("hostile value", "command lines of 1-4 options (hypothesis)", "no traceback",
              cases=len(tried))  # fmt: skip
