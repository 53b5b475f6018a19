"""Family "an option taken and ignored" (harden9 item 4): an option given where it does nothing
(``muscle detect --calibration`` for a recording that holds pressure, ``simulate ramp
--hours 3``, ``monitor --source replay:x.h5 --grid 8x12``, ``station --member a`` without
``--group``) is refused in one line naming it, never taken without a word: the user would
believe it acted. Every command declares where each of its options applies
(:mod:`texsense.commands._applies`); what only a file can tell (the recording's quantity, the
report's mode) is refused where it is read, in the same words.

The table below has a row for every declared rule of every command (a new rule without a row
fails :func:`test_every_rule_has_a_row`) and for the checks made once a file is read; each row
runs ``texsense ARGV`` in one child process. The same options where they apply are accepted.
"""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from faults._families import batch, one_line, small_recording, two_postures
from texsense import Layout, Recording
from texsense.apps.posture.features import FeatureSet
from texsense.apps.posture.model import PostureModel
from texsense.cli import COMMANDS, build_parser
from texsense.commands._applies import check_given, leaf_parser, rules_of
from texsense.exceptions import ParameterError
from texsense.io import save

#: (the option refused, argv): an option given where it has no effect
ROWS = [
    # files read first: a calibration for pressure, a bed's settings for a seat
    ("--calibration", ["muscle", "detect", "rec.h5", "--calibration", "lin.json"]),
    ("--calibration", ["stocking", "report", "rec.h5", "--calibration", "lin.json"]),
    ("--calibration", ["monitor", "--source", "replay:rec.h5", "--calibration", "lin.json",
                       "--no-posture", "--port", "PORT"]),
    ("--model", ["report", "rec.h5", "--mode", "seat", "--model", "m.joblib", "-o", "r.html"]),
    ("--turn-every", ["report", "rec.h5", "--mode", "seat", "--turn-every", "60", "-o", "r.html"]),
    ("--threshold", ["report", "rec.h5", "--mode", "foot", "--threshold", "40", "-o", "r.html"]),
    ("--reposition-min", ["report", "cap.h5", "--reposition-min", "30", "-o", "r.html"]),
    ("--reposition-min", ["report", "rec.h5", "--mode", "foot", "--reposition-min", "30",
                          "-o", "r.html"]),
    ("--turn-every", ["report", "rec.h5", "--turn-every", "60", "-o", "r.html"]),  # guessed: seat
    # simulate: every option outside its protocols and modes
    ("--hours", ["simulate", "ramp", "--hours", "3", "-o", "x.h5"]),
    ("--calibration", ["simulate", "steps", "--calibration", "c.json", "-o", "x.h5"]),
    ("--levels", ["simulate", "ramp", "--levels", "1,2", "-o", "x.h5"]),
    ("--falling", ["simulate", "loads", "--falling", "-o", "x.h5"]),
    ("--max", ["simulate", "steps", "--max", "5", "-o", "x.h5"]),
    ("--cycles", ["simulate", "calibration", "--cycles", "3", "-o", "x.h5"]),
    ("--hold", ["simulate", "ramp", "--hold", "3", "-o", "x.h5"]),
    ("--p3", ["simulate", "ramp", "--p3", "3", "-o", "x.h5"]),
    ("--duration", ["simulate", "ramp", "--duration", "3", "-o", "x.h5"]),
    ("--speed", ["simulate", "random", "--speed", "30", "-o", "x.h5"]),
    ("--speed", ["simulate", "night", "--speed", "30", "-o", "x.h5"]),
    ("--spacer", ["simulate", "mats", "--spacer", "textile-3mm", "--broker", "mqtt://h"]),
    ("--seed", ["simulate", "mats", "--seed", "3", "--broker", "mqtt://h"]),
    ("--output", ["simulate", "device", "--link", "l", "-o", "x.h5"]),
    ("--csv", ["simulate", "night", "-o", "x.h5", "--csv", "x.csv"]),
    ("--sample-hz", ["simulate", "night", "-o", "x.h5", "--sample-hz", "20"]),
    ("--truth", ["simulate", "ramp", "-o", "x.h5", "--truth", "t.h5"]),
    ("--mat", ["simulate", "ramp", "-o", "x.h5", "--mat", "bed"]),
    ("--link", ["simulate", "night", "-o", "x.h5", "--link", "l"]),
    ("--load", ["simulate", "mats", "--broker", "mqtt://h", "--load", "person"]),
    ("--failures", ["simulate", "ramp", "-o", "x.h5", "--failures"]),
    ("--count", ["simulate", "device", "--link", "l", "--count", "3"]),
    ("--broker", ["simulate", "night", "-o", "x.h5", "--broker", "mqtt://h"]),
    ("--prefix", ["simulate", "ramp", "-o", "x.h5", "--prefix", "ward"]),
    ("--beds", ["simulate", "device", "--link", "l", "--beds", "1"]),
    ("--check", ["calibrate", "wizard", "--no-check", "--check", "2", "-o", "c.json"]),
    # monitor's own
    ("--turn-every", ["monitor", "--turn-every", "30", "--port", "PORT"]),
    ("--no-posture", ["monitor", "--model", "m.joblib", "--no-posture", "--port", "PORT"]),
    ("--in-use-drift", ["monitor", "--source", "replay:rec.h5", "--in-use-drift", "off",
                        "--port", "PORT"]),
    ("--interval", ["monitor", "--source", "replay:rec.h5", "--interval", "0.9",
                    "--port", "PORT"]),
    ("--count-possible", ["monitor", "--interval", "off", "--count-possible", "--port", "PORT"]),
    ("--count-possible", ["monitor", "--source", "replay:rec.h5", "--count-possible",
                          "--port", "PORT"]),
    # station
    ("--virtual-beds", ["station", "--config", "w.toml", "--virtual-beds", "1"]),
    ("--speed", ["station", "--config", "w.toml", "--speed", "10"]),
    ("--virtual-calibrations", ["station", "--config", "w.toml", "--virtual-calibrations", "d"]),
    ("--virtual-prefix", ["station", "--config", "w.toml", "--virtual-prefix", "ward"]),
    ("--broker-password-file", ["station", "--virtual-mats", "1", "--broker-password-file",
                                "p.txt"]),
    ("--broker-ca", ["station", "--virtual-mats", "1", "--broker-ca", "ca.pem"]),
    ("--broker-cert", ["station", "--virtual-mats", "1", "--broker-cert", "c.pem"]),
    ("--broker-key", ["station", "--virtual-mats", "1", "--broker-key", "k.pem"]),
    ("--mat-credentials", ["station", "--broker", "mqtt://h", "--virtual-mats", "1",
                           "--mat-credentials", "c.toml"]),
    ("--member", ["station", "--virtual-mats", "1", "--member", "a"]),
    ("--checkpoint-every", ["station", "--virtual-mats", "1", "--checkpoint-every", "5"]),
    ("--workers", ["station", "--virtual-mats", "1", "--workers", "2"]),
    # fits and processing
    ("--drift-kind", ["hysteresis", "fit", "c.csv", "-o", "m.json", "--drift-kind", "prony"]),
    ("--drift-clock", ["hysteresis", "fit", "c.csv", "-o", "m.json", "--drift-clock", "time"]),
    ("--drift-rest-rate", ["hysteresis", "fit", "c.csv", "-o", "m.json", "--drift-rest-rate",
                           "0.5"]),
    ("--drift-rest-rate", ["hysteresis", "fit", "c.csv", "-o", "m.json", "--drift", "s.csv",
                           "--drift-clock", "thesis", "--drift-rest-rate", "0.5"]),
    ("--cells", ["hysteresis", "fit", "c.csv", "-o", "m.json", "--method", "thesis",
                 "--cells", "8"]),
    ("--smoothing", ["hysteresis", "fit", "c.csv", "-o", "m.json", "--method", "thesis",
                     "--smoothing", "0.1"]),
    ("--folds", ["hysteresis", "fit", "c.csv", "-o", "m.json", "--method", "thesis",
                 "--folds", "3"]),
    ("--rest-rate", ["drift", "fit", "s.csv", "-o", "d.json", "--clock", "time",
                     "--rest-rate", "0.5"]),
    ("--workers", ["process", "cap.h5", "--calibration", "lin.json", "-o", "o.h5",
                   "--workers", "2"]),
    ("--rotate", ["posture", "evaluate", "rec.h5", "--rotate"]),
    ("--rotate", ["posture", "train", "rec.h5", "--rotate", "-o", "m.joblib"]),
    # harden10: the commands audited since
    ("--back-label", ["posture", "evaluate", "post.h5", "--back-label", "b"]),
    ("--back-label", ["posture", "train", "post.h5", "--back-label", "b", "-o", "m.joblib"]),
    ("--c", ["posture", "evaluate", "post.h5", "--classifier", "naive-bayes", "--c", "2"]),
    ("--c", ["posture", "train", "post.h5", "--classifier", "lda", "--c", "2", "-o", "m.joblib"]),
    ("--group", ["posture", "train", "post.h5", "--group", "subject", "-o", "m.joblib"]),
    ("--no-mirror", ["posture", "evaluate", "post.h5", "--no-mirror"]),
    ("--mirror", ["posture", "evaluate", "post.h5", "--mirror", "left:right"]),
    *((flag, ["posture", command, "post.h5", "--features", "centre,areas4", flag, *value,
              *(["-o", "m.joblib"] if command == "train" else [])])
      for command in ("evaluate", "train")
      for flag, value in (("--align", []), ("--log", []), ("--pool", ["2"]))),
    ("--range", ["study", "post.h5", "--range", "3", "-o", "st"]),
    ("--name", ["export", "mcu", "mat.json", "-o", "m.bin", "--name", "mat"]),
    ("--accept-truncated", ["export", "mcu", "mat.json", "-o", "m.bin", "--accept-truncated"]),
    ("--like", ["export", "mcu", "mat.json", "-o", "m.bin", "--like", "cap0.h5"]),
    ("--capacity", ["export", "mcu", "lin.json", "--like", "cap.h5", "-o", "m.bin",
                    "--capacity", "8"]),
    ("--all", ["health", "cap.h5", "--json", "--all"]),
    ("--chunk-frames", ["process", "cap0.h5", "--calibration", "mat.json", "-o", "o.csv",
                        "--chunk-frames", "2"]),
    ("--interval", ["process", "cap0.h5", "--calibration", "mat.json", "-o", "o.csv",
                    "--interval", "0.9"]),
    ("--no-hysteresis", ["process", "cap.h5", "--calibration", "lin.json", "-o", "o.h5",
                         "--no-hysteresis"]),
    ("--no-drift", ["process", "cap.h5", "--calibration", "lin.json", "-o", "o.h5",
                    "--no-drift"]),
    ("--in-use-drift", ["process", "cap.h5", "--calibration", "lin.json", "-o", "o.h5",
                        "--in-use-drift", "off"]),
    ("--thickness-mm", ["calibrate", "mat", "--material", "textile-3mm", "--baseline", "cap0.h5",
                        "--uniform", "cap1.h5", "--pressure", "1", "--thickness-mm", "3",
                        "-o", "c.json"]),
    ("--rest-s", ["seat-sessions", "-n", "1", "--rest-s", "5", "-o", "ss"]),
    ("--kind", ["drift", "fit", "r.csv", "--history", "model.json", "--kind", "prony"]),
    ("--output", ["drift", "fit", "r.csv", "-o", "d.json"]),
    ("--turn-every", ["station", "--virtual-mats", "1", "--turn-every", "30", "--port", "PORT"]),
    ("--turn-every", ["station", "--config", "w.toml", "--turn-every", "30", "--port", "PORT"]),
    # a ward file whose every mat sets it itself: the option reaches none
    ("--turn-every", ["station", "--config", "own.toml", "--turn-every", "30", "--port", "PORT"]),
    ("--reposition-min", ["station", "--config", "own.toml", "--reposition-min", "30", "--port",
                          "PORT"]),
    *((flag, ["monitor", "--mode", "foot", flag, value, "--port", "PORT"])
      for flag, value in (("--threshold", "40"), ("--threshold-unit", "kPa"),
                          ("--reposition-min", "30"), ("--offload-min", "2"))),
    ("--count-possible", ["monitor", "--mode", "foot", "--count-possible", "--port", "PORT"]),
]  # fmt: skip

#: the source options of monitor, record and the wizard x a source that does not read it
#: (generated: every option x every command that has them)
_TAIL = {"monitor": ["--port", "PORT"], "record": ["-o", "new.h5"],
         "calibrate wizard": ["-o", "c.json"]}  # fmt: skip
_VALUES = {"--speed": "3", "--grid": "3x4", "--sampling-frequency": "10", "--multiplexer": "m:f",
           "--capdac-pf": "5"}  # fmt: skip
ROWS += [
    (flag, [*command.split(), "--source", "serial:/dev/nothing" if flag == "--speed" else "virtual",
            flag, value, *tail])
    for command, tail in _TAIL.items()
    for flag, value in _VALUES.items()
]  # fmt: skip

#: (argv): the same options where they apply: accepted by the check (not run)
ACCEPTED = [
    ["simulate", "night", "--hours", "3", "-o", "x.h5"],
    ["simulate", "steps", "--levels", "1,2", "--falling", "-o", "x.h5"],
    ["simulate", "device", "--link", "l", "--speed", "3", "--seed", "2"],
    ["simulate", "mats", "--broker", "mqtt://h", "--count", "3", "--speed", "2"],
    ["monitor", "--source", "replay:rec.h5", "--speed", "3"],
    ["monitor", "--source", "iio:d", "--grid", "3x4", "--capdac-pf", "5"],
    ["monitor", "--bed", "--turn-every", "30", "--calibration", "c.json", "--interval", "0.9"],
    ["monitor", "--source", "virtual-bed", "--turn-every", "30", "--count-possible"],
    ["station", "--virtual-mats", "2", "--virtual-beds", "1", "--speed", "3"],
    ["station", "--broker", "mqtts://u@h", "--broker-ca", "ca.pem", "--group", "g",
     "--member", "a", "--db", "postgresql://x"],
    ["hysteresis", "fit", "c.csv", "-o", "m.json", "--drift", "s.csv", "--drift-kind", "prony"],
    ["hysteresis", "fit", "c.csv", "-o", "m.json", "--method", "lsq", "--cells", "8"],
    ["drift", "fit", "s.csv", "--history", "m.json", "-o", "d.json", "--rest-rate", "0.5"],
    ["drift", "fit", "s.csv", "--kind", "prony"],
    ["export", "mcu", "m.json", "-o", "m.c", "--name", "mat", "--like", "r.h5",
     "--accept-truncated"],
    ["health", "cap.h5", "--all"],
    ["process", "a.h5", "--calibration", "lin.json", "-o", "o.h5", "--chunk-frames", "2"],
    ["seat-sessions", "--rounds", "3", "--rest-s", "5", "-o", "s"],
    ["posture", "train", "r.h5", "--classifier", "auto", "--group", "subject", "-o", "m"],
    ["posture", "evaluate", "r.h5", "--features", "elements,back", "--back-label", "b", "--log",
     "--pool", "2", "--c", "2"],
    ["posture", "evaluate", "r.h5", "--log"],
    ["station", "--virtual-mats", "2", "--turn-every", "30"],
    ["station", "--config", "w.toml", "--turn-every", "30"],
    ["monitor", "--mode", "seat", "--threshold", "40", "--offload-min", "2"],
    ["process", "a.h5", "b.h5", "--calibration", "lin.json", "-o", "out", "--workers", "2"],
    ["calibrate", "wizard", "--check", "2", "-o", "c.json"],
    ["posture", "evaluate", "rec.h5", "--align", "--rotate"],
]  # fmt: skip


def _all_rules() -> dict[str, list[str]]:
    """Every command (as its words) -> the flags its rules name."""
    parser = build_parser(COMMANDS)
    out: dict[str, list[str]] = {}

    def walk(p: argparse.ArgumentParser, words: list[str]) -> None:
        subs = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        for action in subs:
            for name, sp in action.choices.items():
                walk(sp, [*words, name])
        if not subs and rules_of(p):
            out[" ".join(words)] = [r.flag for r in rules_of(p)]

    walk(parser, [])
    return out


def test_every_rule_has_a_row():
    nested = ("hysteresis", "drift", "calibrate", "muscle", "stocking", "posture", "export")
    rows = {(flag, " ".join(argv[:2]) if argv[0] in nested else argv[0]) for flag, argv in ROWS}
    missing = [f"{command} {flag}" for command, flags in _all_rules().items() for flag in flags
               if (flag, command) not in rows]  # fmt: skip
    assert missing == [], missing


@pytest.fixture
def folder(tmp_path):
    save(small_recording(), tmp_path / "rec.h5")
    cap = Recording(np.full((4, 12), 10.0), np.arange(4.0), Layout.grid(3, 4), "capacitance", "pF")
    save(cap, tmp_path / "cap.h5")
    from texsense.cli import main

    assert main(["calibrate", "linear", "--like", str(tmp_path / "cap.h5"), "--gain", "2",
                 "--to", "pressure:N/cm2", "-o", str(tmp_path / "lin.json")]) == 0  # fmt: skip
    (tmp_path / "w.toml").write_text('[[mat]]\nid = "a"\nlayout = "grid:3x4"\n')
    y = np.array(["left", "right"] * 10)  # a bed's side model (its sides are all it needs here)
    frames = np.random.default_rng(0).random((20, 12))
    PostureModel(FeatureSet(("elements",)), Layout.grid(3, 4), "logistic").fit(frames, y).save(
        tmp_path / "sides.joblib"
    )
    (tmp_path / "own.toml").write_text('[[mat]]\nid = "a"\nlayout = "grid:3x4"\nbed = true\n'
                                       'model = "sides.joblib"\nturn_every_min = 60\n'
                                       'reposition_min = 15\n')  # fmt: skip
    for name, level in (("cap0.h5", 10.0), ("cap1.h5", 12.0)):  # (a mat calibration's)
        values = level + 0.01 * np.random.default_rng(int(level)).standard_normal((6, 12))
        save(Recording(values, np.arange(6.0), Layout.grid(3, 4), "capacitance", "pF"),
             tmp_path / name)  # fmt: skip
    assert main(["calibrate", "mat", "--material", "textile-3mm", "--baseline",
                 str(tmp_path / "cap0.h5"), "--uniform", str(tmp_path / "cap1.h5"), "--pressure",
                 "1", "-o", str(tmp_path / "mat.json")]) == 0  # fmt: skip
    save(two_postures(), tmp_path / "post.h5")
    assert main(["simulate", "calibration", "--csv", str(tmp_path / "r.csv")]) == 0
    assert main(["hysteresis", "fit", str(tmp_path / "r.csv"), "--method", "thesis", "--grid",
                 "20", "-o", str(tmp_path / "model.json")]) == 0  # fmt: skip
    return tmp_path


def test_an_option_that_has_no_effect_is_refused(folder, fault_row):
    from conftest import free_port

    argvs = [[str(free_port()) if a == "PORT" else a for a in argv] for _, argv in ROWS]
    results, _, _ = batch(argvs, folder, timeout=600)
    wrong = []
    for (flag, argv), (rc, _out, err) in zip(ROWS, results, strict=True):
        try:
            line = one_line(rc, err, flag)
            assert "no effect" in line, line
        except AssertionError as e:
            wrong.append(f"{' '.join(argv)}: {str(e)[:300]}")
    assert wrong == [], f"{len(wrong)} of {len(ROWS)}:\n" + "\n".join(wrong)
    commands = sorted({" ".join(argv[:2]) if argv[0] in ("simulate", "calibrate", "hysteresis")
                       else argv[0] for _, argv in ROWS})  # fmt: skip
    fault_row("no effect", f"{len(ROWS)} options given where they have no effect "
              f"({len(commands)} commands and modes)", "clear error", "the option named, and "
              "where it applies", cases=len(ROWS))  # fmt: skip


def test_the_same_options_where_they_apply_pass_the_check():
    parser = build_parser(COMMANDS)
    for argv in ACCEPTED:
        args = parser.parse_args(argv)
        assert leaf_parser(parser, args) is not None
        try:
            check_given(parser, args, argv)
        except ParameterError as e:
            raise AssertionError(f"{' '.join(argv)}: {e}") from None
