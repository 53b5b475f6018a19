"""``texsense station``: a ward of mats over MQTT, with an overview page (docs/station.md)."""

from __future__ import annotations

import argparse
import logging
import tomllib
from pathlib import Path
from typing import Any

from texsense.commands import HELP
from texsense.commands.monitor import virtual_bed_model
from texsense.exceptions import FormatError, ParameterError
from texsense.layout import Layout
from texsense.monitor import sources
from texsense.monitor.store import open_store
from texsense.posture import PostureModel
from texsense.stages import load_chain
from texsense.station.broker import Broker, parse_broker_url
from texsense.station.virtual import VirtualMats
from texsense.station.ward import MatConfig, Station
from texsense.workflows import bed_calibration, seat_calibration


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``station`` command."""
    p = sub.add_parser(
        "station",
        help=HELP["station"],
        description="Ingest many mats at once — each with its layout, calibration, pipeline "
        "state, exposure and reposition alerts — from an MQTT broker (a Mosquitto of its own "
        "on loopback unless --broker names one) and from serial, IIO or replay sources named "
        "in a TOML file; serve the ward overview, one dashboard per mat, REST and a "
        "WebSocket.",
    )
    p.add_argument(
        "--virtual-mats", type=int, default=0, metavar="N",
        help="N simulated people on virtual seats and bed mats (alternating), publishing "
        "through the broker",
    )  # fmt: skip
    p.add_argument(
        "--speed", type=float, default=1.0,
        help="virtual mats: simulated seconds per second (a frame per 1.6 s at 1)",
    )  # fmt: skip
    p.add_argument("--config", type=Path, help="TOML file of the ward's mats (docs/station.md)")
    p.add_argument("--broker", help="mqtt://[user:password@]host[:port] or mqtts://... "
                   "(default: start Mosquitto on loopback)")  # fmt: skip
    p.add_argument(
        "--mats", default="texsense/+/frames",
        help="MQTT topic filter of this station's mats (split a site: 'ward3/+/frames')",
    )  # fmt: skip
    p.add_argument("--virtual-prefix", default="texsense", help="topic prefix of virtual mats")
    p.add_argument("--reposition-min", type=float, default=20.0, help="reposition interval")
    p.add_argument("--turn-every", type=float, default=120.0, metavar="MIN",
                   help="beds: turning-schedule alert after this many minutes on one side "
                   "(default 120; a mat of the ward file is a bed with `bed = true`)")  # fmt: skip
    p.add_argument(
        "--db", default="station.sqlite", help="event store: a SQLite file or postgresql://..."
    )
    p.add_argument("--record-dir", type=Path, default=Path("recordings"))
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=8766)
    p.add_argument("--token", help="required on every request when binding beyond loopback")
    p.set_defaults(run=run)


def _layout(spec: Any, where: str) -> Any:
    from texsense.io import load

    if isinstance(spec, str) and spec.startswith("grid:"):
        try:
            rows, cols = (int(v) for v in spec[5:].lower().split("x"))
        except ValueError:
            raise ParameterError(f"{where}: layout {spec!r}: expected grid:ROWSxCOLS") from None
        return Layout.grid(rows, cols)
    if isinstance(spec, str):
        return load(spec).layout
    raise ParameterError(f"{where}: layout must be 'grid:ROWSxCOLS' or a recording's path")


def read_config(
    path: Path, reposition_min: float, turn_every_min: float = 120.0
) -> tuple[list[Any], dict[str, Any]]:
    """Mats and local sources of a TOML ward file::

    [[mat]]
    id = "bed12"                      # the topic segment: <prefix>/bed12/frames
    layout = "grid:64x32"             # or the path of a recording of the mat
    calibration = "bed12.json"        # omit for a mat that sends pressure
    source = "mqtt"                   # or "serial:/dev/ttyUSB0", "iio:DIR", "replay:FILE"
    bed = true                        # a bed: turning schedule and at-risk regions ...
    model = "sides.joblib"            # ... on the sides this posture model reports
    turn_every_min = 120              # default: --turn-every
    """
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise FormatError(path, f"cannot read: {e.strerror}") from None
    except tomllib.TOMLDecodeError as e:
        raise FormatError(path, f"not TOML: {e}") from None
    mats: list[Any] = []
    local: dict[str, sources.Source] = {}
    calibrations: dict[str, Any] = {}  # a file named by many mats is read once
    for k, m in enumerate(doc.get("mat", [])):
        where = f"{path} [[mat]] #{k + 1}"
        if not isinstance(m, dict) or "id" not in m or "layout" not in m:
            raise FormatError(path, f"[[mat]] #{k + 1} needs an id and a layout")
        layout = _layout(m["layout"], where)
        cal = None
        if m.get("calibration"):
            key = str(m["calibration"])
            if key not in calibrations:
                calibrations[key] = load_chain(key)
            cal = calibrations[key]
        quantity = "capacitance" if cal is not None else "pressure"
        kind, _, rest = str(m.get("source", "mqtt")).partition(":")
        if kind == "serial":
            local[m["id"]] = sources.SerialSource(rest, layout)
        elif kind == "iio":
            local[m["id"]] = sources.IIOSource(rest, layout)
        elif kind == "replay":
            local[m["id"]] = sources.ReplaySource(Path(rest), speed=1.0, loop=True)
        elif kind != "mqtt":
            raise FormatError(path, f"[[mat]] #{k + 1}: unknown source {m.get('source')!r}")
        bed = m.get("bed", False)
        if not isinstance(bed, bool):
            raise FormatError(path, f"[[mat]] #{k + 1}: bed must be true or false, got {bed!r}")
        model = None
        if bed:
            if not m.get("model"):
                raise FormatError(path, f"[[mat]] #{k + 1}: a bed needs model = \"FILE\", a "
                                  "posture model of sides (texsense posture train)")  # fmt: skip

            model = PostureModel.load(str(m["model"]))
        every = float(m.get("turn_every_min", turn_every_min))
        mats.append(MatConfig(str(m["id"]), layout, cal, quantity, str(m.get("source", "mqtt")),
                              float(m.get("reposition_min", reposition_min)), bed=bed,
                              posture_model=model, turn_every_min=every))  # fmt: skip
    return mats, local


def run(args: argparse.Namespace) -> int:
    """Run ``texsense station``."""
    from texsense.station.server import serve_ward

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    if args.virtual_mats < 0:
        raise ParameterError("--virtual-mats must be >= 0")
    mats, local = (
        read_config(args.config, args.reposition_min, args.turn_every) if args.config else ([], {})
    )
    if not mats and not args.virtual_mats:
        raise ParameterError("no mats: give --virtual-mats N and/or --config ward.toml")
    own = None
    if args.broker:
        url = parse_broker_url(args.broker)
    else:
        own = Broker().start()
        url = own.url
        print(f"texsense station: Mosquitto on {url}")
    try:
        background = []
        if args.virtual_mats:
            vm = VirtualMats(args.virtual_mats, url, prefix=args.virtual_prefix, speed=args.speed)
            beds, sides = None, None
            if args.virtual_mats > 1:
                beds, sides = bed_calibration(), virtual_bed_model()
            mats += vm.configs(seat_calibration(), beds, args.reposition_min, sides,
                               args.turn_every)  # fmt: skip
            background.append(vm.run())
        station = Station(url, mats, topic=args.mats, store=open_store(args.db),
                          record_dir=args.record_dir)  # fmt: skip
        background += [station.consume(mat_id, src) for mat_id, src in local.items()]
        print(f"texsense station: {len(mats)} mats -> http://{args.host}:{args.port}/")
        serve_ward(station, host=args.host, port=args.port, token=args.token,
                   background=background)  # fmt: skip
    finally:
        if own is not None:
            own.stop()
    return 0
