"""``texsense posture evaluate|train`` and ``texsense study``: posture classification and the
error-modelling study (docs/posture.md)."""

from __future__ import annotations

import argparse
import html
import json
from pathlib import Path
from typing import Any

import numpy as np

from texsense.apps.posture.defaults import DEFAULT_C, DEFAULT_CLASSIFIER, DEFAULT_FEATURES
from texsense.apps.posture.evaluate import (
    C_PARAMETER,
    CLASSIFIERS,
    check_classes,
    loso,
    make_classifier,
)
from texsense.apps.posture.features import KINDS, FeatureSet, mirror_samples, reduce_maps
from texsense.apps.posture.model import PostureModel
from texsense.apps.posture.smoothing import window_vote
from texsense.apps.posture.study import ErrorStudy, plot_study, sensor_hysteresis_model
from texsense.commands import HELP
from texsense.commands._applies import Rule, given, only_where, refuse_unless
from texsense.commands._options import add_accept_truncated
from texsense.commands._tables import confusion_lines, natural_key, text_table
from texsense.data.files import check_not_input, make_folder, pyplot, save_figure, write_text
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError
from texsense.io import load

#: The thesis's feature kinds (§6.3.2), used when feature options are given without --features.
THESIS_KINDS = "elements,centre,areas4,areas16"


def _selection_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", type=Path, help="recording with per-frame labels (any format)")
    p.add_argument("--label", default="posture", help="the label to classify (default posture)")
    p.add_argument("--where", action="append", default=[], metavar="LABEL",
                   help="keep only frames where a boolean label is true (repeatable)")  # fmt: skip
    p.add_argument("--drop", action="append", default=[], metavar="VALUE",
                   help="leave out frames whose label has this value (repeatable)")  # fmt: skip
    p.add_argument("--every", type=int, default=1, help="use every N-th frame (default 1)")
    add_accept_truncated(p)


def _feature_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group(
        "classifier and features",
        f"default: {describe_defaults()} (chosen by benchmarks/posture_defaults.py, "
        "docs/posture.md); any feature option below replaces the default feature set",
    )
    g.add_argument("--classifier", choices=tuple(CLASSIFIERS), default=None,
                   help=f"default {DEFAULT_CLASSIFIER}; naive-bayes is the thesis's (and brings "
                   "the thesis's features unless feature options are given)")  # fmt: skip
    g.add_argument("--c", type=float, default=None, metavar="C",
                   help="regularisation of logistic / SVMs (default: the default classifier's "
                   f"{DEFAULT_C}, else the registry's)")  # fmt: skip
    g.add_argument("--features", default=None,
                   help=f"comma-separated feature kinds of {', '.join(KINDS)} (with options: "
                   "elements,centre,areas4,areas16, the thesis's)")  # fmt: skip
    g.add_argument("--back-label", default="back", help="label holding the back sensor")
    g.add_argument("--align", action="store_true", help="centre each map's centre of force")
    g.add_argument("--rotate", action="store_true", help="with --align: turn to the body axis")
    g.add_argument("--log", action="store_true", help="log(1 + value) of element values")
    g.add_argument("--pool", type=int, default=None, help="mean of N x N element blocks")
    g.add_argument("--mirror", nargs="?", const="auto", metavar="MAP",
                   help="also train on left-right mirrored frames; MAP names each label's mirror "
                   "image ('2:3,4:6,1' = 2 and 3 swap, 4 and 6 swap, 1 is its own); without "
                   "MAP the map the recording declares. Default: on when the recording "
                   "declares one (PMD does)")  # fmt: skip
    g.add_argument("--no-mirror", action="store_true", help="no mirrored training copies")
    only_where(p, [
        Rule("--rotate", lambda a: a.align, "--align (a map is turned once centred)"),
        Rule("--back-label", lambda a: "back" in _feature_set(a).kinds,
             "the back feature (--features ...,back)"),
        *(Rule(flag, lambda a: "elements" in _feature_set(a).kinds,
               "the element values (--features with elements: the others are computed from "
               "the map as it is)") for flag in ("--align", "--log", "--pool")),
        Rule("--c", lambda a: (a.classifier or DEFAULT_CLASSIFIER) in C_PARAMETER,
             f"a classifier with a regularisation C ({', '.join(C_PARAMETER)})"),
    ])  # fmt: skip


def describe_defaults() -> str:
    """The default classifier and features in words."""
    c = "" if DEFAULT_C is None else f" (C={DEFAULT_C:g})"
    return f"{DEFAULT_CLASSIFIER}{c} on {DEFAULT_FEATURES.describe()}"


def _classifier(args: argparse.Namespace) -> tuple[str, Any]:
    """(name shown, unfitted estimator) of --classifier / --c or the defaults."""
    name = args.classifier or DEFAULT_CLASSIFIER
    c = args.c if args.c is not None or args.classifier else DEFAULT_C
    return name + ("" if c is None else f" C={c:g}"), make_classifier(name, c)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``posture`` and ``study`` commands."""
    p = sub.add_parser(
        "posture",
        help=HELP["posture"],
        description="Classify frames of a labelled recording (thesis chapter 6).",
    )
    ps = p.add_subparsers(dest="posture_command", metavar="WHAT")
    ps.required = True
    e = ps.add_parser("evaluate", help="leave-one-subject-out accuracy, per subject, confusion")
    _selection_args(e)
    e.add_argument("--group", default="subject", help="the label naming the subject")
    e.add_argument(
        "--window", type=float, metavar="S",
        help="also report the accuracy of a vote over the last S seconds (live smoothing)",
    )  # fmt: skip
    _feature_args(e)
    e.add_argument("--json", action="store_true", help="print the report as JSON")
    e.set_defaults(run=run_evaluate)
    t = ps.add_parser("train", help="train a classifier on all frames and save it")
    _selection_args(t)
    _feature_args(t)
    t.add_argument("--group", default="subject",
                   help="the label naming the subject (the auto classifier chooses by subject; "
                   "without it, its first candidate)")  # fmt: skip
    t.add_argument("-o", "--output", type=Path, required=True, help="model file (joblib)")
    t.set_defaults(run=run_train)
    only_where(t, [Rule("--group", lambda a: a.classifier == "auto",
                        "--classifier auto (it chooses its set-up by subject)")])  # fmt: skip

    s = sub.add_parser(
        "study",
        help=HELP["study"],
        description="Thesis §6.4: one reference pattern per posture (the mean of its frames), "
        "test patterns with modelled errors, recognition rate and class distances.",
    )
    _selection_args(s)
    s.add_argument("--align", action="store_true", help="centre maps before averaging")
    s.add_argument("--pool", type=int, default=1, help="average N x N blocks of elements")
    s.add_argument("--range", type=float, default=5.0,
                   help="scale non-pressure data so the largest reference value is this many "
                   "N/cm² (default 5)")  # fmt: skip
    s.add_argument("-o", "--output", type=Path, required=True, help="report folder")
    s.set_defaults(run=run_study)


def _frames(args: argparse.Namespace) -> tuple[Recording, np.ndarray, np.ndarray]:
    """The recording, the selected frame indices and their labels."""
    rec = load(args.recording, accept_truncated=args.accept_truncated)
    labels = rec.labels
    if args.label not in labels:
        raise ParameterError(
            f"{args.recording}: no label {args.label!r}; labels: {', '.join(labels) or 'none'}"
        )
    keep = np.ones(rec.n_frames, dtype=bool)
    for name in args.where:
        if name not in labels:
            raise ParameterError(f"{args.recording}: no label {name!r} for --where")
        keep &= np.asarray(labels[name]).astype(bool)
    y = np.asarray(labels[args.label])
    for value in args.drop:
        keep &= y.astype(str) != value
    if args.every < 1:
        raise ParameterError(f"--every must be >= 1, got {args.every}")
    idx = np.flatnonzero(keep)[:: args.every]
    if idx.size == 0:
        raise ParameterError("no frames left after --where/--drop")
    check_classes(y[idx], f"{args.recording}: the frames selected (--where, --drop, --every) "
                  f"of label {args.label!r}")  # fmt: skip
    return rec, idx, y[idx]


def _feature_set(args: argparse.Namespace) -> FeatureSet:
    """The features of the options; when none is given, the default set (the thesis's
    with ``--classifier naive-bayes``: the thesis's classifier on the thesis's features)."""
    if args.features is None and not (args.align or args.rotate or args.log or args.pool):
        return FeatureSet(tuple(THESIS_KINDS.split(","))) if args.classifier == "naive-bayes" else (
            DEFAULT_FEATURES)  # fmt: skip
    kinds = tuple(k.strip() for k in (args.features or THESIS_KINDS).split(",") if k.strip())
    return FeatureSet(kinds, align=args.align, rotate=args.rotate, log=args.log,
                      pool=args.pool or 1)  # fmt: skip


def _mirror_map(args: argparse.Namespace, rec: Recording) -> dict[str, str] | None:
    """The label -> mirror-image map of ``--mirror``; without the option the map the
    recording declares for the label, if any; None with ``--no-mirror``."""
    if args.no_mirror:
        if args.mirror is not None:
            raise ParameterError("--mirror and --no-mirror contradict each other")
        refuse_unless(args, "--no-mirror", args.label in rec.meta.get("mirror", {}),
                      "a recording that declares a mirror map for the label",
                      f"{args.recording} declares none for {args.label!r}")  # fmt: skip
        return None
    if args.mirror is None:
        declared = rec.meta.get("mirror", {}).get(args.label)
        return None if declared is None else {str(k): str(v) for k, v in declared.items()}
    if args.mirror == "auto":
        declared = rec.meta.get("mirror", {})
        if args.label not in declared:
            raise ParameterError(
                f"{args.recording} declares no mirror map for label {args.label!r}; "
                "pass one: --mirror '2:3,4:6,1'"
            )
        return {str(k): str(v) for k, v in declared[args.label].items()}
    table = _mirror_table(args.mirror)
    values = sorted({str(v) for v in np.asarray(rec.labels[args.label])}, key=natural_key)
    refuse_unless(args, "--mirror", bool(set(table) & set(values)),
                  f"a map that names values of the label {args.label!r}",
                  f"{args.recording} holds {', '.join(values[:10])}")  # fmt: skip
    return table


def _mirror_table(text: str) -> dict[str, str]:
    """The label -> mirror image table of ``--mirror A:B,C``."""
    table: dict[str, str] = {}
    for item in text.split(","):
        a, sep, b = (part.strip() for part in item.partition(":"))
        if not a or (sep and not b):
            raise ParameterError(f"--mirror: cannot read {item!r} (expected A:B or A)")
        b = b if sep else a
        for k, v in ((a, b), (b, a)):
            if table.get(k, v) != v:
                raise ParameterError(f"--mirror: {k!r} has two mirror images")
            table[k] = v
    return table


def _back(args: argparse.Namespace, rec: Recording, fs: FeatureSet, idx: np.ndarray) -> Any:
    if "back" not in fs.kinds:
        return None
    if args.back_label not in rec.labels:
        raise ParameterError(f"the back feature needs a label {args.back_label!r} in the file")
    return np.asarray(rec.labels[args.back_label], dtype=np.float64)[idx]


def run_evaluate(args: argparse.Namespace) -> int:
    """Run ``texsense posture evaluate``."""
    rec, idx, y = _frames(args)
    if args.group not in rec.labels:
        raise ParameterError(f"{args.recording}: no label {args.group!r} naming the subjects")
    groups = np.asarray(rec.labels[args.group])[idx]
    fs = _feature_set(args)
    back = _back(args, rec, fs, idx)
    X = fs.transform(rec.frames[idx], rec.layout, back)
    extra = None
    mirror = _mirror_map(args, rec)
    if mirror is not None:
        flipped, y_m, src = mirror_samples(rec.frames[idx], y, rec.layout, mirror)
        b = None if back is None else back[src]
        extra = (fs.transform(flipped, rec.layout, b), y_m, groups[src])
    name, estimator = _classifier(args)
    report = loso(X, y, groups, estimator, extra=extra, show_progress=not args.json)
    window = None
    if args.window is not None:
        window = _window_accuracy(rec.times[idx], y, report.predictions, groups, args.window)
    if args.json:
        print(json.dumps({"classifier": name, "frames": int(idx.size),
                          "mirror": mirror, "window": window,
                          "features": fs.to_dict(), **report.to_dict()}, indent=1))  # fmt: skip
        return 0
    mirrored = "" if mirror is None else ", mirrored training copies"
    print(f"{name} on {fs.describe()}{mirrored}")
    print(
        f"{idx.size} frames, {len(report.per_subject)} subjects, "
        f"{len(report.labels)} classes of {args.label!r}: leave-one-subject-out accuracy "
        f"{report.accuracy:.1%} (worst {report.minimum[0]}: {report.minimum[1]:.1%})"
    )
    if window is not None:
        print(
            f"a vote over the last {args.window:g} s (each subject's frames in time order): "
            f"{window['accuracy']:.1%} (worst {window['minimum']['subject']}: "
            f"{window['minimum']['accuracy']:.1%}), per frame {report.accuracy:.1%}"
        )

    rows = [
        [s, f"{a:.1%}"]
        for s, a in sorted(report.per_subject.items(), key=lambda kv: natural_key(kv[0]))
    ]
    print("\n".join("  " + line for line in text_table([args.group, "accuracy"], rows)))
    print("confusion (rows true, columns predicted):")
    names = rec.meta.get("postures") if args.label == "posture" else None
    print("\n".join(confusion_lines(report.labels, report.confusion, names)))
    return 0


def _window_accuracy(
    times: np.ndarray, y: np.ndarray, pred: np.ndarray, groups: np.ndarray, window_s: float
) -> dict[str, Any]:
    """Accuracy of the live vote over the last ``window_s`` s, per subject (mean) and worst.
    The vote restarts only at a new subject: posture changes within a subject's recording
    are voted across, as they would be live."""
    smoothed = window_vote(times, pred, window_s, sequences=groups)
    hit = smoothed == y
    per = {str(s): float(np.mean(hit[groups == s])) for s in np.unique(groups)}
    worst = min(per, key=per.__getitem__)
    return {
        "window_s": window_s,
        "accuracy": float(np.mean(list(per.values()))),
        "per_subject": per,
        "minimum": {"subject": worst, "accuracy": per[worst]},
    }


def run_train(args: argparse.Namespace) -> int:
    """Run ``texsense posture train``."""

    check_not_input(args.output, [args.recording])
    rec, idx, y = _frames(args)
    fs = _feature_set(args)
    name, estimator = _classifier(args)
    model = PostureModel(fs, rec.layout, estimator, mirror=_mirror_map(args, rec))
    model.classifier_name = name
    if args.group not in rec.labels and given(args, "--group"):
        raise ParameterError(f"{args.recording}: no label {args.group!r} naming the subjects")
    groups = np.asarray(rec.labels[args.group])[idx] if args.group in rec.labels else None
    model.fit(rec.frames[idx], y, _back(args, rec, fs, idx), groups=groups)
    model.save(args.output)
    chose = getattr(model.estimator, "choice_", None)
    assert model.classes_ is not None  # fitted
    print(f"trained {name}{'' if chose is None else f' ({chose})'} on {fs.describe()} "
          f"({idx.size} frames, {len(model.classes_)} classes) -> {args.output}")  # fmt: skip
    return 0


def run_study(args: argparse.Namespace) -> int:
    """Run ``texsense study``: reference patterns, all sweeps, report.html + numbers.json."""
    plt = pyplot()
    check_not_input(args.output, [args.recording])
    rec, idx, y = _frames(args)
    frames = np.nan_to_num(rec.frames[idx].astype(np.float64))
    layout = rec.layout
    if args.align or args.pool > 1:
        frames, layout = reduce_maps(frames, layout, align=args.align, rotate=True, pool=args.pool)
    classes = np.unique(y)
    refs = np.vstack([frames[y == c].mean(axis=0) for c in classes])
    scaled = rec.quantity != "pressure"
    refuse_unless(args, "--range", scaled, "a recording that is not pressure (its values "
                  "scaled to N/cm²)", f"{args.recording} holds pressure")  # fmt: skip
    if scaled:
        refs *= args.range / refs.max()
    study = ErrorStudy(refs, layout, classes.tolist(), hysteresis_model=sensor_hysteresis_model())
    results = study.run()
    out = args.output
    make_folder(out)
    fig = plot_study(results, f"{args.recording.name}: {classes.size} classes, modelled errors")
    try:
        save_figure(fig, out / "study.png", dpi=100)
    finally:
        plt.close(fig)
    numbers = {
        "source": str(args.recording),
        "classes": [str(c) for c in classes],
        "elements": layout.n_elements,
        "frames_averaged": int(idx.size),
        "scaled_to_ncm2": args.range if scaled else None,
        "results": ErrorStudy.to_dict(results),
    }
    write_text(out / "numbers.json", json.dumps(numbers, indent=1))
    write_text(out / "report.html", _report_html(numbers))
    print(f"wrote {out / 'report.html'}, {out / 'study.png'}, {out / 'numbers.json'}")
    return 0


def _report_html(numbers: dict[str, Any]) -> str:
    """A self-contained page: the figure and one table per error source."""
    esc = html.escape
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>texsense study</title>",
        "<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto}"
        "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;"
        "padding:2px 8px;text-align:right}</style></head><body>",
        f"<h1>Error-modelling study: {esc(numbers['source'])}</h1>",
        f"<p>{len(numbers['classes'])} reference patterns ({numbers['elements']} elements, "
        f"means of {numbers['frames_averaged']} frames); 32 training and 15 test patterns per "
        "class and level; naive Bayes (thesis §6.4-6.5.1).</p>",
        "<img src='study.png' alt='recognition rate and class distances' style='width:100%'>",
    ]
    for source, pts in numbers["results"].items():
        head = "".join(f"<th>{p['level']:g}</th>" for p in pts)
        rows = [
            ("recognition rate", [f"{100 * p['rate']:.0f} %" for p in pts]),
            ("d_md (between)", [f"{p['d_md']:.2f}" for p in pts]),
            ("d_ms (within)", [f"{p['d_ms']:.2f}" for p in pts]),
        ]
        body = "".join(
            f"<tr><th>{name}</th>" + "".join(f"<td>{v}</td>" for v in vals) + "</tr>"
            for name, vals in rows
        )
        parts.append(f"<h2>{esc(source)}</h2><table><tr><th>level</th>{head}</tr>{body}</table>")
    parts.append("<p>Every number is in numbers.json.</p></body></html>")
    return "\n".join(parts)
