"""``texsense monitor``: the live dashboard (docs/monitor.md)."""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import logging
import signal
import socket
from collections.abc import Callable
from pathlib import Path

from texsense.apps.bed import BedWatch
from texsense.apps.posture.model import PostureModel
from texsense.apps.views import guess_mode
from texsense.commands import HELP
from texsense.commands._applies import Rule, no_effect, only_where
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import StageChain, load_chain
from texsense.data.files import cache_folder, check_writable, kept_or_made
from texsense.data.layout import Layout, parse_orientation
from texsense.exceptions import ParameterError
from texsense.monitor import ExposureTracker, Monitor, sources
from texsense.monitor.sources import Source
from texsense.monitor.store import open_store
from texsense.monitor.web import Access, is_loopback, resolve_token, stop_on_sigterm


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``monitor`` command."""
    p = sub.add_parser(
        "monitor",
        help=HELP["monitor"],
        description="Read a sensor live, compensate it, record it and show it in a web "
        "dashboard. Without --source: a simulated person on the virtual 96-element seat.",
    )
    add_source_options(p)
    p.add_argument("--calibration", type=Path, help="mat calibration (texsense pipeline calibrate)")
    p.add_argument("--model", type=Path, help="posture model (texsense posture train)")
    p.add_argument(
        "--no-posture",
        action="store_true",
        help="no posture classification (the virtual seat and bed train one otherwise; the "
        "bed mode needs it)",
    )
    p.add_argument("--threshold", type=float, default=32.0, help="exposure threshold (default 32)")
    p.add_argument("--threshold-unit", default="mmHg", help="its unit (default mmHg)")
    p.add_argument(
        "--reposition-min",
        type=float,
        default=20.0,
        help="reposition alert after this many minutes of exposure (5-120, default 20)",
    )
    p.add_argument(
        "--offload-min",
        type=float,
        default=1.0,
        help="minutes below the threshold that reset the exposure (default 1)",
    )
    p.add_argument(
        "--bed",
        action="store_true",
        help="a bed mat: turning schedule and at-risk regions (on with --source virtual-bed; "
        "--model must report sides: supine, prone, left, right, sitting)",
    )
    p.add_argument(
        "--turn-every",
        type=float,
        default=120.0,
        metavar="MIN",
        help="bed: turning-schedule alert after this many minutes on one side (default 120)",
    )
    p.add_argument(
        "--mode",
        choices=("auto", "seat", "bed", "foot", "generic"),
        default="auto",
        help="what the mat is under: the words of events and alerts, the unit and colour scale "
        "(auto: bed for the virtual bed and --bed, from the file for a replay, else seat; "
        "foot raises no seated/left events and no exposure alerts)",
    )
    p.add_argument(
        "--in-use-drift",
        choices=("on", "off"),
        default="on",
        help="on (default, except in foot mode: a foot is never still): correct the drift from "
        "the mat in use — stillness, an empty mat (docs/drift.md); off: the calibration's "
        "laboratory drift stage",
    )
    p.add_argument(
        "--interval",
        default="0.95",
        metavar="LEVEL|off",
        help="bounds of every value at this level (default 0.95; shown on hover, in the region "
        "table, and an alert says whether the threshold is exceeded with that confidence); "
        "off: none. Needs a calibration with held-out residuals (a spacer preset)",
    )
    p.add_argument(
        "--count-possible",
        action="store_true",
        help="count elements only possibly above the threshold (their upper bound is, their "
        "lower is not) toward the reposition alert too",
    )
    p.add_argument("--record", action="store_true", help="record from the start")
    p.add_argument("--record-dir", type=Path, default=Path("recordings"))
    p.add_argument(
        "--db",
        default="texsense-monitor.sqlite",
        help="sessions and events: a SQLite file or postgresql://user:password@host/db",
    )
    add_web_options(p, 8765)
    p.set_defaults(run=run_monitor)
    only_where(p, MONITOR_RULES)


_CALIBRATED = "a calibrated capacitance mat (--calibration, or --source virtual, virtual-bed)"
#: Where ``monitor``'s own options apply (:mod:`texsense.commands._applies`).
MONITOR_RULES = [
    Rule("--turn-every", lambda a: a.bed or a.source == "virtual-bed",
         "a bed (--bed, or --source virtual-bed)"),
    Rule("--no-posture", lambda a: a.model is None, "the virtual mats' own posture "
         "model: a --model is used whatever it says"),
    *(Rule(flag, lambda a: _calibrated(a), _CALIBRATED)
      for flag in ("--in-use-drift", "--interval", "--count-possible")),
    Rule("--count-possible", lambda a: a.interval != "off", "bounds (--interval LEVEL)"),
    *(Rule(flag, lambda a: a.mode != "foot", "exposure alerts (not --mode foot)")
      for flag in ("--threshold", "--threshold-unit", "--reposition-min", "--offload-min",
                   "--count-possible")),
]  # fmt: skip


def _calibrated(args: argparse.Namespace) -> bool:
    """Whether the monitor's source is compensated: a ``--calibration``, or a virtual mat's
    own (a replay of pressure, checked once it is read: :func:`build_monitor`)."""
    if args.calibration is not None:
        return True
    cls = sources.available_sources().get(str(args.source).partition(":")[0])
    return cls is None or cls.default_calibration.__func__ is not (  # type: ignore[attr-defined]
        Source.default_calibration.__func__  # type: ignore[attr-defined]
    )


#: The source options of ``monitor``, ``record`` and ``calibrate wizard``, and the sources
#: that read each (every source declares what it reads: ``Source.reads``).
SOURCE_OPTIONS = {
    "--speed": "--source virtual, virtual-bed or replay:FILE",
    "--grid": "--source serial, iio or mqtt",
    "--sampling-frequency": "--source iio",
    "--multiplexer": "--source iio",
    "--capdac-pf": "--source iio",
}


def _reads(flag: str) -> Callable[[argparse.Namespace], bool]:
    def applies(args: argparse.Namespace) -> bool:
        cls = sources.available_sources().get(str(args.source).partition(":")[0])
        return cls is None or flag in cls.reads  # (an unknown source: its own error)

    return applies


def add_source_options(p: argparse.ArgumentParser) -> None:
    """``--source`` and what a source needs (speed, grid, the IIO converter's settings):
    shared by ``monitor`` and ``record``."""
    p.add_argument("--source", default="virtual", help=sources.source_help())
    p.add_argument(
        "--speed",
        type=float,
        default=1.0,
        help="virtual seat / replay: times faster than real time (0: as fast as possible)",
    )
    p.add_argument(
        "--grid",
        default=None,
        metavar="ROWSxCOLS",
        help="iio/mqtt: the sensor's grid (e.g. 15x16); serial: only for a device that does "
        "not announce its layout",
    )
    p.add_argument(
        "--orientation",
        default=None,
        metavar="KIND[:EDGE]|EDGE=LABEL,...|none",
        help="how the mat lies, if its device does not say: bed, seat or foot with its head, "
        "front or toes at the top of the map (row 1), or e.g. bed:bottom for the head at the "
        "last row; or top=head,bottom=foot,...; without it a mat names no left or right",
    )
    p.add_argument(
        "--sampling-frequency",
        type=float,
        default=None,
        metavar="HZ",
        help="iio: the converter's conversion rate (the driver picks its nearest)",
    )
    p.add_argument(
        "--multiplexer",
        default=None,
        metavar="MODULE:FUNCTION",
        help="iio: a function called with each element's index before it is read (a module "
        "name or a .py file, e.g. mymux.py:select)",
    )
    p.add_argument(
        "--capdac-pf",
        type=float,
        default=None,
        metavar="PF",
        help="iio: CAPDAC offset subtracted before conversion (pF)",
    )
    only_where(p, [Rule(flag, _reads(flag), where) for flag, where in SOURCE_OPTIONS.items()])


def add_web_options(p: argparse.ArgumentParser, port: int) -> None:
    """The options of a server (``monitor`` and ``station``): address, port, token, and the
    names and page origins it answers to (docs/monitor.md, "Security")."""
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=port)
    p.add_argument(
        "--token",
        default=None,
        help="required on every request; mandatory when binding beyond loopback (every user "
        "of the machine can read it here: prefer --token-file or $TEXSENSE_TOKEN)",
    )
    p.add_argument("--token-file", type=Path, default=None,
                   help="read the token from this file (its first line)")  # fmt: skip
    p.add_argument(
        "--allow-host", action="append", default=[], metavar="NAME",
        help="also answer to this Host name (the server's DNS name, a reverse proxy's); "
        "repeatable",
    )  # fmt: skip
    p.add_argument(
        "--allow-origin", action="append", default=[], metavar="URL",
        help="also serve pages of this origin (e.g. https://portal.example); repeatable",
    )  # fmt: skip


def web_access(args: argparse.Namespace, what: str) -> Access:
    """The :class:`~texsense.monitor.web.Access` of the command's options; refuses binding
    beyond loopback without a token."""

    token = resolve_token(args.token, args.token_file)
    if not is_loopback(args.host) and not token:
        raise ParameterError(
            f"binding {args.host} exposes the {what} beyond this machine: give a token "
            "(--token-file FILE, $TEXSENSE_TOKEN or --token)"
        )
    return Access(token, bind=args.host, hosts=args.allow_host, origins=args.allow_origin)


def page_url(args: argparse.Namespace, token: str | None) -> str:
    """The address to open in a browser."""
    host = "127.0.0.1" if args.host in ("0.0.0.0", "::") else args.host
    host = f"[{host}]" if ":" in host else host
    return f"http://{host}:{args.port}/" + (f"?token={token}" if token else "")


def _grid(args: argparse.Namespace) -> Layout | None:
    """``--grid ROWSxCOLS``, or None."""
    if not args.grid:
        return None
    try:
        rows, cols = (int(v) for v in args.grid.lower().split("x"))
    except ValueError:
        raise ParameterError(f"--grid: expected ROWSxCOLS, got {args.grid!r}") from None
    return Layout.grid(rows, cols)


def load_function(spec: str) -> Callable[[int], None]:
    """``module:function`` or ``path/to/file.py:function`` -> the function."""
    where, _, name = spec.rpartition(":")
    if not where or not name:
        raise ParameterError(f"--multiplexer: expected MODULE:FUNCTION, got {spec!r}")
    try:
        if where.endswith(".py"):
            spec_ = importlib.util.spec_from_file_location(Path(where).stem, where)
            if not Path(where).is_file() or spec_ is None or spec_.loader is None:
                raise ParameterError(f"--multiplexer: no such file {where!r}")
            module = importlib.util.module_from_spec(spec_)
            spec_.loader.exec_module(module)
        else:
            module = importlib.import_module(where)
    except ImportError as e:
        raise ParameterError(f"--multiplexer: cannot import {where!r}: {e}") from None
    fn = getattr(module, name, None)
    if not callable(fn):
        raise ParameterError(f"--multiplexer: {where!r} has no function {name!r}")
    return fn


def default_calibration(source: str) -> StageChain | None:
    """The calibration a source brings (the virtual mats' own), or None."""
    cls = sources.available_sources().get(source.partition(":")[0])
    return None if cls is None else cls.default_calibration()


def open_source(args: argparse.Namespace, *, loop: bool = True) -> Source:
    """The source named by ``--source`` (no calibration: what ``record`` and the wizard
    need), turned as ``--orientation`` says; a replay starts again at its end with
    ``loop``. The sources are those of the registry
    (:func:`texsense.monitor.sources.open_source`)."""
    given = getattr(args, "orientation", None)
    try:
        orientation = None if given is None else parse_orientation(given)
    except ParameterError as e:
        raise ParameterError(f"--{e}") from None
    options = sources.SourceOptions(
        speed=args.speed,
        grid=_grid(args),
        sampling_frequency=args.sampling_frequency,
        multiplexer=load_function(args.multiplexer) if args.multiplexer else None,
        capdac_pF=args.capdac_pf,
        loop=loop,
    )
    source = sources.open_source(args.source, options)
    if orientation is not None:
        source.layout = source.layout.with_orientation(orientation or None)
    return source


def build_monitor(args: argparse.Namespace) -> Monitor:
    """Source, pipeline, tracker, model, store -> a Monitor."""
    source = open_source(args)
    calibration: StageChain | None
    if args.calibration is not None:
        calibration = load_chain(args.calibration)
    else:
        calibration = default_calibration(args.source)
    pipeline = None
    if args.calibration is not None and source.quantity != "capacitance":
        raise ParameterError(
            f"{no_effect('--calibration', 'a source of capacitance')}; {source.name} sends "
            f"{source.quantity} ({source.unit})"
        )
    if source.quantity == "capacitance" and calibration is not None:
        pipeline = monitor_pipeline(args, calibration, source, _mode(args, source, None))
    raw_only = source.quantity == "capacitance" and pipeline is None
    if raw_only:
        logging.getLogger("texsense.monitor").warning(
            "%s: no calibration: showing and recording raw capacitance (pF); "
            "'texsense calibrate wizard' makes one",
            source.name,
        )
    tracker = ExposureTracker(
        source.layout,
        threshold=args.threshold,
        unit=args.threshold_unit,
        reposition_min=args.reposition_min,
        offload_min=args.offload_min,
        count_possible=getattr(args, "count_possible", False),
    )
    model = PostureModel.load(args.model) if args.model else None
    if raw_only and (model is not None or args.bed):
        raise ParameterError("--model and --bed need pressure: give the mat's --calibration")
    if model is None and args.source == "virtual" and not args.no_posture:
        model = virtual_seat_model(_virtual_calibration(args).id)
    bed = None
    if args.bed and args.no_posture:
        raise ParameterError("--bed needs the side model: drop --no-posture")
    if args.bed or (args.source == "virtual-bed" and not args.no_posture):
        if model is None and args.source == "virtual-bed":
            model = virtual_bed_model(_virtual_calibration(args).id)
        if model is None:
            raise ParameterError("--bed needs --model: a posture model of sides")
        bed = BedWatch(
            source.layout,
            interval_min=args.turn_every,
            threshold=args.threshold,
            unit=args.threshold_unit,
            offload_min=args.offload_min,
        )
    monitor = Monitor(
        source,
        pipeline=pipeline,
        tracker=tracker,
        posture_model=model,
        store=open_store(args.db),
        record_dir=args.record_dir,
        bed=bed,
        mode=_mode(args, source, bed),
    )
    if args.record:
        monitor.start_recording()
    return monitor


def monitor_pipeline(
    args: argparse.Namespace, calibration: StageChain, source: Source, mode: str
) -> Pipeline:
    """The monitor's pipeline: the in-use drift correction where the mat's use allows it
    (not in foot mode: never still), bounds where the calibration has held-out residuals;
    the log says which and why not."""
    log = logging.getLogger("texsense.monitor")
    in_use = getattr(args, "in_use_drift", "on") == "on"
    if in_use and mode == "foot":
        log.warning("%s: in-use drift correction off: a foot sensor is loaded at every step and "
                    "never still; the calibration's drift stage runs", source.name)  # fmt: skip
        in_use = False
    level = str(getattr(args, "interval", "0.95"))
    interval = None
    if level != "off":
        try:
            interval = float(level)
        except ValueError:
            raise ParameterError(f"--interval: a level (e.g. 0.95) or off, not {level!r}") from None
    try:
        pipeline = Pipeline(calibration, source.layout, in_use=in_use, interval=interval)
    except ParameterError as e:
        if interval is None or "held-out" not in str(e):
            raise
        log.warning("%s: no bounds: %s", source.name, e)
        pipeline = Pipeline(calibration, source.layout, in_use=in_use)
    if pipeline.in_use_note:
        log.warning("%s: in-use drift correction off: %s", source.name, pipeline.in_use_note)
    return pipeline


def _mode(args: argparse.Namespace, source: Source, bed: BedWatch | None) -> str:
    """``--mode``, or for ``auto``: bed with a bed watch, the file's for a replay, else seat."""
    mode = getattr(args, "mode", "auto")
    if mode != "auto":
        return str(mode)
    if bed is not None or args.source == "virtual-bed":
        return "bed"
    rec = getattr(source, "rec", None)
    if rec is not None:
        return guess_mode(rec.layout, rec.meta)
    return "seat"


def _virtual_calibration(args: argparse.Namespace) -> StageChain:
    """The calibration a virtual mat's posture model is trained with: the mat's own one
    (whichever ``--calibration`` is in use)."""
    calibration = default_calibration(args.source)
    if calibration is None:
        raise ParameterError(f"--source {args.source} brings no calibration of its own")
    return calibration


def _cached_model(
    name: str, what: str, seconds: int, train: Callable[[], PostureModel]
) -> PostureModel:
    """A posture model cached under ~/.cache/texsense/NAME.joblib, trained by ``train()``
    when missing (a broken cache is rebuilt, and said so). The name carries the id of the
    virtual mat's calibration the model is trained on, so a texsense whose compensation
    changed trains a new one instead of reading an old one. Processes started together train
    it once: the others wait for it (:func:`~texsense.data.files.made_once`)."""
    path = cache_folder() / f"{name}.joblib"

    def training() -> PostureModel:
        print(
            f"texsense monitor: training {what} on simulated people (once, about {seconds} s; "
            f"cached in {path})",
            flush=True,
        )
        model = train()
        model.save(path)
        return model

    return kept_or_made(path, _kept_model, training)


def _kept_model(path: Path) -> PostureModel | None:
    """The posture model kept at ``path``, or None (none, or one that cannot be read: said)."""
    if not path.is_file():
        return None
    try:
        return PostureModel.load(path)
    except Exception as e:
        logging.getLogger("texsense.monitor").warning("rebuilding %s: %s", path, e)
        return None


def virtual_seat_model(calibration_id: str) -> PostureModel:
    """A posture model for the virtual seat, trained on simulated sessions of other people
    (compensated pressure, §6.5.2) with the calibration ``calibration_id``
    (:func:`texsense.calibration.workflows.seat_calibration`), cached under ~/.cache/texsense."""
    from texsense.apps.posture.training import train_virtual_seat_model

    return _cached_model(
        f"virtual-seat-posture-v3-{calibration_id}",
        "the virtual seat's posture model",
        15,
        train_virtual_seat_model,
    )


def virtual_bed_model(calibration_id: str) -> PostureModel:
    """A model of the side a person lies on for the virtual bed, trained on other simulated
    people (compensated pressure) with the calibration ``calibration_id``
    (:func:`texsense.calibration.workflows.bed_calibration`), cached under ~/.cache/texsense."""
    from texsense.apps.posture.training import train_virtual_bed_model

    return _cached_model(
        f"virtual-bed-sides-v1-{calibration_id}",
        "the virtual bed's side model",
        40,
        train_virtual_bed_model,
    )


def check_port_free(host: str, port: int) -> None:
    """Fail before the (slow) set-up when the port is taken."""
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError as e:
            raise ParameterError(
                f"cannot listen on {host}:{port} ({e.strerror}): is a monitor already "
                "running? Choose another --port"
            ) from None


def run_monitor(args: argparse.Namespace) -> int:
    """Run ``texsense monitor`` (until Ctrl-C or SIGTERM)."""

    from texsense.monitor.server import serve

    access = web_access(args, "monitor")
    check_port_free(args.host, args.port)
    check_writable(args.record_dir, "--record-dir", folder=True)  # now, not at the first recording
    if not str(args.db).startswith(("postgresql://", "postgres://")):
        check_writable(args.db, "--db")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    with stop_on_sigterm():  # SIGTERM before the server runs: like Ctrl-C
        monitor = build_monitor(args)
        url = page_url(args, access.token)
        print(f"texsense monitor: {monitor.source.name} -> {url}", flush=True)
        stopped = serve(monitor, host=args.host, port=args.port, access=access)
    if stopped is not None:
        print(f"texsense monitor: stopped ({signal.Signals(stopped).name})", flush=True)
    return 0
