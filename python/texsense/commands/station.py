"""``texsense station``: a ward of mats over MQTT, with an overview page (docs/station.md)."""

from __future__ import annotations

import argparse
import difflib
import gc
import logging
import os
import re
import signal
import socket
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from texsense.apps.posture.model import PostureModel
from texsense.calibration.workflows import bed_calibration, seat_calibration
from texsense.commands import HELP
from texsense.commands._applies import Rule, only_where, refuse_unless
from texsense.commands._options import RANGES
from texsense.commands.monitor import (
    add_web_options,
    check_port_free,
    page_url,
    virtual_bed_model,
    web_access,
)
from texsense.compensation.stages import load_chain
from texsense.data import budget
from texsense.data.files import check_writable, kept_or_made, open_regular, toml_loads
from texsense.data.layout import Layout, parse_orientation
from texsense.data.protocol import payload_limit
from texsense.exceptions import FormatError, ParameterError, shown
from texsense.monitor import sources
from texsense.monitor.store import open_store
from texsense.monitor.web import resolve_token, stop_on_sigterm
from texsense.station.broker import check_mat_id, mat_topic, parse_broker_url, station_broker
from texsense.station.virtual import VirtualMats
from texsense.station.ward import MIN_STALE_S, MatConfig, Station
from texsense.station.workers import Supervisor, watch_parent, worker_env, worker_name


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
    p.add_argument("--virtual-beds", type=int, metavar="K",
                   help="of the virtual mats, only the first K even-numbered ones are beds "
                   "(default: every second one)")  # fmt: skip
    p.add_argument(
        "--speed", type=float, default=1.0,
        help="virtual mats: simulated seconds per second (a frame per 1.6 s at 1)",
    )  # fmt: skip
    p.add_argument("--virtual-calibrations", type=Path, metavar="DIR",
                   help="virtual mats: read their calibrations from DIR (virtual-seat.json, "
                   "virtual-bed.json), made and written there by the first station that needs "
                   "them (the members of a group share one folder instead of each calibrating "
                   "at its start)")  # fmt: skip
    p.add_argument("--config", type=Path, help="TOML file of the ward's mats (docs/station.md)")
    p.add_argument("--broker", help="a site broker: mqtt://[user@]host[:port] or mqtts://... "
                   "(default: start a Mosquitto of its own on loopback)")  # fmt: skip
    p.add_argument("--broker-password-file", type=Path, metavar="FILE",
                   help="the broker user's password (its first line); or set "
                   "$TEXSENSE_BROKER_PASSWORD")  # fmt: skip
    p.add_argument("--broker-ca", metavar="FILE", help="mqtts: the CA certificate(s) to trust "
                   "(default: the system's)")  # fmt: skip
    p.add_argument("--broker-cert", metavar="FILE", help="mqtts: a client certificate")
    p.add_argument("--broker-key", metavar="FILE", help="mqtts: the client certificate's key")
    p.add_argument("--mat-credentials", type=Path, default=Path("mat-credentials.toml"),
                   metavar="FILE", help="own broker: the MQTT mats' passwords, made when "
                   "missing (mode 0600; default mat-credentials.toml)")  # fmt: skip
    p.add_argument("--stale-after", type=float, default=MIN_STALE_S, metavar="S",
                   help="a mat is stale after two of its frame periods without a frame, and "
                   f"not before S s (default {MIN_STALE_S:g}; more for jittery links or a "
                   "loaded machine)")  # fmt: skip
    p.add_argument("--refuse-after", type=float, default=10.0, metavar="S",
                   help="refuse a mat whose frames have had another element count for this "
                   "long (and 10 messages in a row; default 10 s)")  # fmt: skip
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
    group = p.add_argument_group(
        "a group of stations (docs/station.md, 'A group of stations'): every member with the "
        "same ward, --broker and --db postgresql://..."
    )
    group.add_argument("--group", metavar="NAME", help="join the group NAME: its members share "
                       "the mats, PostgreSQL decides who holds which, and a mat whose "
                       "station dies is taken over from its checkpoint")  # fmt: skip
    group.add_argument("--member", metavar="NAME", help="this member's name in the group "
                       "(default: HOSTNAME:PORT; a member that comes back under its name gets "
                       "its mats back)")  # fmt: skip
    group.add_argument("--checkpoint-every", type=float, default=2.0, metavar="S",
                       help="checkpoint each held mat this often (and after every alert "
                       "event; default 2 s)")  # fmt: skip
    group.add_argument("--workers", type=int, default=1, metavar="N", help="this member as N "
                       "processes (members MEMBER.wK on PORT+K) under a supervisor that "
                       "restarts a worker that dies: a member on N cores (default 1)")  # fmt: skip
    add_web_options(p, 8766)
    p.set_defaults(run=run)
    only_where(p, STATION_RULES)


_BEDS = "beds (a mat of --config with bed = true, or a virtual bed: --virtual-mats 2 or more)"
_REPOSITION = "mats whose ward file entry has no reposition_min of its own, or virtual mats"

#: Where the station's options apply (:mod:`texsense.commands._applies`).
STATION_RULES = [
    *(Rule(flag, lambda a: a.virtual_mats > 0, "virtual mats (--virtual-mats N)") for flag in
      ("--virtual-beds", "--speed", "--virtual-calibrations", "--virtual-prefix")),
    *(Rule(flag, lambda a: bool(a.broker), "a site broker (--broker)") for flag in
      ("--broker-password-file", "--broker-ca", "--broker-cert", "--broker-key")),
    Rule("--mat-credentials", lambda a: not a.broker,
         "the station's own broker (without --broker: a site broker keeps its own)"),
    *(Rule(flag, lambda a: bool(a.group), "a group (--group NAME)") for flag in
      ("--member", "--checkpoint-every", "--workers")),
    Rule("--turn-every", lambda a: a.config is not None or _virtual_beds(a) > 0, _BEDS),
]  # fmt: skip


def _virtual_beds(args: argparse.Namespace) -> int:
    """How many of the virtual mats are beds (every second one unless --virtual-beds)."""
    return args.virtual_mats // 2 if args.virtual_beds is None else args.virtual_beds


def _layout(spec: Any, where: str, named: Any) -> Any:
    from texsense.io import load

    if isinstance(spec, str) and spec.startswith("grid:"):
        dims = re.fullmatch(r"([0-9]+)x([0-9]+)", spec[5:].strip().lower())
        if dims is None:
            raise ParameterError(f"{where}: layout {spec!r}: expected grid:ROWSxCOLS")
        try:
            return Layout.grid(int(dims[1]), int(dims[2]))
        except ParameterError as e:  # 0 rows, a grid beyond the budget: the ward file named
            raise ParameterError(f"{where}: layout {spec!r}: {e}") from None
    if isinstance(spec, str):
        return load(named("layout", spec, "recording")).layout
    raise ParameterError(f"{where}: layout must be 'grid:ROWSxCOLS' or a recording's path")


#: The keys of a ``[[mat]]`` of a ward file that name a path, and the kind each must be
#: (:data:`texsense.io.named.PATH_KINDS`; ``source``: its source's, e.g. replay: a recording).
#: Every path in a ward file is relative to the ward file's folder (docs/station.md).
PATH_KEYS = {"layout": "recording", "calibration": "file", "model": "file", "source": "source"}

#: The keys of a ``[[mat]]`` of a ward file and their TOML types.
MAT_KEYS: dict[str, type | tuple[type, ...]] = {
    "id": str, "layout": str, "calibration": str, "source": str, "bed": bool, "model": str,
    "orientation": str,
    "reposition_min": (int, float), "turn_every_min": (int, float),
}  # fmt: skip


def _known_keys(
    path: Path, where: str, table: dict[str, Any], known: dict[str, type | tuple[type, ...]]
) -> None:
    """Refuse a key ``known`` does not name (saying the nearest known one) or a value of
    another type: a misspelt key would otherwise be ignored without a word (``calibraton``:
    the mat ran uncalibrated; ``Bed``: not as a bed)."""
    for key, value in table.items():
        if key not in known:
            near = difflib.get_close_matches(key.lower(), list(known), n=1, cutoff=0.6)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise FormatError(
                path, f"{where}: unknown key {key!r}{hint}; known: {', '.join(known)}"
            )
        kinds = known[key]
        if not isinstance(value, kinds) or (isinstance(value, bool) and kinds == (int, float)):
            want = kinds.__name__ if isinstance(kinds, type) else "a number"
            want = {"str": "a text", "bool": "true or false", "list": "a list"}.get(want, want)
            raise FormatError(path, f"{where}: {key} must be {want}, got {value!r}")


def _paths_of(ward: Path, k: int) -> Any:
    """``named(key, value, kind)``: the path ``value`` of the key ``key`` of the ward file's
    ``[[mat]]`` number ``k`` (from 0), relative to the ward file's folder and of ``kind``
    (:func:`texsense.io.named.named_path`; ``"source"``: a source's spec, its path
    resolved), or one :class:`FormatError` naming the file, the ``[[mat]]`` and the key."""

    def named(key: str, value: Any, kind: str) -> Any:
        try:
            if kind == "source":
                return sources.resolve_spec(str(value), ward)
            from texsense.io.named import named_path  # (h5py: with the recordings)

            return named_path(str(value), ward, kind)
        except ParameterError as e:
            raise FormatError(ward, f"[[mat]] #{k + 1}: {key} {shown(value, 200)}: {e}") from None

    return named


def _ward_document(path: Path) -> dict[str, Any]:
    """The TOML of the ward file ``path`` (a regular file within the memory budget), its
    top-level keys checked; anything else is one :class:`FormatError` naming it."""
    try:
        with open_regular(path) as f:  # a regular file only: no FIFO, no device
            budget.check(os.fstat(f.fileno()).st_size, "the ward file", path)
            doc = toml_loads(f.read())
    except FormatError:
        raise  # missing, a folder, a FIFO: said by open_regular, not "not TOML"
    except OSError as e:
        raise FormatError(path, f"cannot read: {e.strerror}") from None
    except UnicodeDecodeError:
        raise FormatError(path, "not UTF-8 text") from None
    except ValueError as e:  # tomllib's, and nested too deeply, too many digits
        raise FormatError(path, f"not TOML: {e}") from None
    _known_keys(path, "the ward file", doc, {"mat": list})
    return doc


def read_config(
    path: Path, reposition_min: float, turn_every_min: float = 120.0
) -> tuple[list[Any], dict[str, Any]]:
    """Mats and local sources of a TOML ward file::

    [[mat]]
    id = "bed12"                      # the topic segment: <prefix>/bed12/frames
    layout = "grid:64x32"             # or the path of a recording of the mat
                                      # (every path: relative to this file's folder)
    orientation = "bed"               # how it lies: bed, seat, foot, bed:bottom, top=head,...
                                      # (default: the calibration's, else none declared)
    calibration = "bed12.json"        # omit for a mat that sends pressure
    source = "mqtt"                   # or "serial:/dev/ttyUSB0", "iio:DIR", "replay:FILE"
    bed = true                        # a bed: turning schedule and at-risk regions ...
    model = "sides.joblib"            # ... on the sides this posture model reports
    turn_every_min = 120              # default: --turn-every
    """
    doc = _ward_document(path)
    mats: list[Any] = []
    local: dict[str, sources.Source] = {}
    calibrations: dict[str, Any] = {}  # a file named by many mats is read once
    for k, m in enumerate(doc.get("mat", [])):
        where = f"{path} [[mat]] #{k + 1}"
        if not isinstance(m, dict) or "id" not in m or "layout" not in m:
            raise FormatError(path, f"[[mat]] #{k + 1} needs an id and a layout")
        _known_keys(path, f"[[mat]] #{k + 1}", m, MAT_KEYS)
        named = _paths_of(path, k)
        for key, option in (
            ("reposition_min", "--reposition-min"),
            ("turn_every_min", "--turn-every"),
        ):
            try:
                RANGES[option].check(float(m.get(key, 20.0)), key)  # as its option's
            except ValueError as e:
                raise FormatError(path, f"[[mat]] #{k + 1}: {e}") from None
        try:
            check_mat_id(m["id"])
        except ParameterError as e:
            raise FormatError(path, f"[[mat]] #{k + 1}: {e}") from None
        layout = _layout(m["layout"], where, named)
        cal = None
        if m.get("calibration"):
            key = str(named("calibration", m["calibration"], "file"))
            if key not in calibrations:
                calibrations[key] = load_chain(key)
            cal = calibrations[key]
        quantity = "capacitance" if cal is not None else "pressure"
        if m.get("orientation") is not None:
            try:
                layout = layout.with_orientation(parse_orientation(m["orientation"]) or None)
            except ParameterError as e:
                raise FormatError(path, f"[[mat]] #{k + 1}: {e}") from None
        elif cal is not None and cal.orientation and not layout.orientation:
            layout = layout.with_orientation(cal.orientation)
        spec = str(m.get("source", "mqtt"))
        if spec != "mqtt":  # a source of this machine, from the registry (docs/station.md)
            spec = named("source", spec, "source")
            try:
                local[m["id"]] = sources.open_source(spec, sources.SourceOptions(grid=layout))
            except ParameterError as e:
                raise FormatError(path, f"[[mat]] #{k + 1}: source {spec!r}: {e}") from None
            if local[m["id"]].layout.n_elements != layout.n_elements:
                raise FormatError(
                    path,
                    f"[[mat]] #{k + 1}: source {spec!r} reads "
                    f"{local[m['id']].layout.n_elements} elements, the layout has "
                    f"{layout.n_elements}",
                )
        bed = m.get("bed", False)
        if not isinstance(bed, bool):
            raise FormatError(path, f"[[mat]] #{k + 1}: bed must be true or false, got {bed!r}")
        model = None
        if bed:
            if not m.get("model"):
                raise FormatError(path, f"[[mat]] #{k + 1}: a bed needs model = \"FILE\", a "
                                  "posture model of sides (texsense posture train)")  # fmt: skip
            model = PostureModel.load(named("model", m["model"], "file"))
        every = float(m.get("turn_every_min", turn_every_min))
        own = frozenset(key for key in ("reposition_min", "turn_every_min") if key in m)
        mats.append(MatConfig(str(m["id"]), layout, cal, quantity, spec,
                              float(m.get("reposition_min", reposition_min)), bed=bed,
                              posture_model=model, turn_every_min=every, own=own))  # fmt: skip
    return mats, local


def site_broker(args: argparse.Namespace) -> Any:
    """The ``--broker`` URL with the password from its file or the environment and the TLS
    files."""

    url = parse_broker_url(args.broker)
    password = url.password
    if args.broker_password_file is not None:
        password = resolve_token(None, args.broker_password_file, {}, "--broker-password-file")
    elif password is None and os.environ.get("TEXSENSE_BROKER_PASSWORD"):
        password = os.environ["TEXSENSE_BROKER_PASSWORD"]
    if password is not None and not url.username:
        raise ParameterError("a broker password needs a user: --broker mqtt://USER@host")
    tls_files = (args.broker_ca, args.broker_cert, args.broker_key)
    if any(tls_files) and not url.tls:
        raise ParameterError("--broker-ca/--broker-cert/--broker-key need an mqtts:// broker")
    for f in tls_files:
        if f is not None and not Path(f).is_file():
            raise ParameterError(f"no such file: {f}")

    return replace(url, password=password, ca_file=args.broker_ca, cert_file=args.broker_cert,
                   key_file=args.broker_key)  # fmt: skip


def own_broker(args: argparse.Namespace, mats: list[Any], local: dict[str, Any], vm: Any) -> Any:
    """Start the station's own broker: (broker, the station's login, the virtual mats'
    logins)."""

    mqtt_mats = {m.id: mat_topic(args.mats, m.id) for m in mats if m.id not in local}
    virtual = vm.topics() if vm is not None else {}
    largest = max((payload_limit(m.layout.n_elements) for m in mats), default=0)
    vmats = max(payload_limit(2048), largest) if vm is not None else largest
    broker, url, logins = station_broker(
        args.mats, mqtt_mats, virtual, args.mat_credentials if mqtt_mats else None,
        max(262_144, vmats + 1024),
    )  # fmt: skip
    where = f"; the mats' passwords are in {args.mat_credentials}" if mqtt_mats else ""
    print(f"texsense station: Mosquitto on {broker.url} (log-in required{where})", flush=True)
    return broker, url, {k: v for k, v in logins.items() if k in virtual}


def run(args: argparse.Namespace) -> int:
    """Run ``texsense station`` (until Ctrl-C or SIGTERM; its own broker stops with it)."""

    worker = as_worker(args)
    access = web_access(args, "ward")
    if worker is None and args.workers > 1:
        return supervise(args)
    check_port_free(args.host, args.port)
    check_writable(args.record_dir, "--record-dir", folder=True)  # now, not at the first recording
    if not str(args.db).startswith(("postgresql://", "postgres://")):
        check_writable(args.db, "--db")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    if args.virtual_mats < 0:
        raise ParameterError("--virtual-mats must be >= 0")
    started: list[Any] = []  # the station's own broker, once it runs
    with stop_on_sigterm():  # SIGTERM before the server runs: like Ctrl-C, clean-up included
        try:
            stopped = _serve(args, access, started)
        finally:
            for broker in started:
                broker.stop()  # the process, and its temporary folder
    if stopped is not None:
        print(f"texsense station: stopped ({signal.Signals(stopped).name})", flush=True)
    return 0


def as_worker(args: argparse.Namespace) -> Any:
    """When this process is a worker of a member (:mod:`texsense.station.workers`): its
    member name and port set in ``args``, its supervisor watched; the worker, else None."""
    try:
        worker = worker_env()
    except ValueError as e:
        raise ParameterError(str(e)) from None
    if worker is None:
        return None
    member = args.member or f"{socket.gethostname()}:{args.port}"
    args.member = worker_name(member, worker.index)
    args.port += worker.index
    args.workers_share = 1.0 / worker.count
    watch_parent(worker.parent)
    return worker


def supervise(args: argparse.Namespace) -> int:
    """``--workers N``: check what every worker needs, then run them
    (:class:`~texsense.station.workers.Supervisor`) until Ctrl-C or SIGTERM."""
    check_group(args, {})  # (without --group, --workers is refused: STATION_RULES)
    for k in range(args.workers):
        check_port_free(args.host, args.port + k)
    argv = getattr(args, "argv", None)
    if argv is None:
        raise ParameterError("--workers: the command line is not known (run it as a command)")
    print(f"texsense station: {args.workers} workers of member "
          f"{args.member or f'{socket.gethostname()}:{args.port}'!r} on ports "
          f"{args.port}-{args.port + args.workers - 1}", flush=True)  # fmt: skip
    return Supervisor([sys.executable, "-m", "texsense.cli", *argv], args.workers).run()


def virtual_calibration(folder: Path | None, kind: str, make: Any) -> Any:
    """The virtual mats' calibration of ``kind`` (seat, bed): ``make()`` (a user's calibration
    of the virtual mat: seconds of a core), or with ``folder`` the file
    ``folder/virtual-KIND.json``, made and written there first by whichever station needs it
    first while the others wait for it (a lock file in the folder): every member of a group
    then reads the same calibration."""
    if folder is None:
        return make()
    path = folder / f"virtual-{kind}.json"

    def calibrating() -> Any:
        print(f"texsense station: calibrating the virtual {kind} into {path}", flush=True)
        make().save(path)
        return load_chain(path)  # what every other member reads

    try:
        folder.mkdir(parents=True, exist_ok=True)
        return kept_or_made(path, lambda p: load_chain(p) if p.exists() else None, calibrating)
    except OSError as e:
        raise ParameterError(f"--virtual-calibrations {folder}: {e.strerror or e}") from None


def check_group(args: argparse.Namespace, local: dict[str, Any]) -> None:
    """What a member of a group needs: a broker and a PostgreSQL that outlive any member,
    and only mats that publish to the broker."""
    if not args.broker:
        raise ParameterError("--group needs --broker: the site's broker, which every member "
                             "reaches and the mats publish to")  # fmt: skip
    if not str(args.db).startswith(("postgresql://", "postgres://")):
        raise ParameterError("--group needs --db postgresql://...: the group's leases, "
                             "checkpoints and events")  # fmt: skip
    if local:
        raise ParameterError(f"a group's mats publish to the broker; {', '.join(local)} "
                             "read(s) a device of this machine (source = ...)")  # fmt: skip


def group_station(
    args: argparse.Namespace, url: Any, mats: list[Any], token: str | None
) -> Station:
    """This member of the group ``--group`` (:mod:`texsense.station.group`)."""
    from texsense.station.group import GroupStation

    host = args.host if args.host not in ("0.0.0.0", "::") else socket.gethostname()
    host = f"[{host}]" if ":" in host else host
    member = args.member or f"{socket.gethostname()}:{args.port}"
    station = GroupStation(url, mats, group=args.group, member=member, db=args.db,
                           page=f"http://{host}:{args.port}/", topic=args.mats,
                           record_dir=args.record_dir, checkpoint_s=args.checkpoint_every,
                           min_stale_s=args.stale_after, refuse_after_s=args.refuse_after,
                           token=token, share=getattr(args, "workers_share", 1.0))  # fmt: skip
    print(f"texsense station: member {member!r} of the group {args.group!r}", flush=True)
    return station


def freeze_built() -> None:
    """Leave what the station has built (every mat's pipeline, tracker and monitor: ~90,000
    objects at 1,000 mats) out of the garbage collector's full collections: one of them took
    ~260 ms of the event loop (issue 38: 1,000 mats on a loaded 2-core machine), a stall of
    every frame waiting meanwhile; after :func:`gc.freeze` it scans only what came since.
    Frozen objects are still freed when nothing refers to them."""
    gc.collect()
    gc.freeze()


def _serve(args: argparse.Namespace, access: Any, started: list[Any]) -> int | None:
    from texsense.station.server import serve_ward

    mats, local = (
        read_config(args.config, args.reposition_min, args.turn_every) if args.config else ([], {})
    )
    refuse_unless(args, "--turn-every", _virtual_beds(args) > 0 or
                  any(m.bed and "turn_every_min" not in m.own for m in mats), _BEDS,
                  f"{args.config} names no bed without its own turn_every_min")  # fmt: skip
    refuse_unless(args, "--reposition-min", bool(args.virtual_mats) or
                  any("reposition_min" not in m.own for m in mats), _REPOSITION,
                  f"every mat of {args.config} has its own reposition_min")  # fmt: skip
    if not mats and not args.virtual_mats:
        if args.config:
            raise FormatError(args.config, "no [[mat]]: a ward file names at least one mat")
        raise ParameterError("no mats: give --virtual-mats N and/or --config ward.toml")
    if args.group:
        check_group(args, local)
    vm = None
    if args.virtual_mats:
        vm = VirtualMats(args.virtual_mats, None, prefix=args.virtual_prefix, speed=args.speed,
                         beds=args.virtual_beds)  # fmt: skip
    background = []
    if args.broker:
        url = site_broker(args)
    else:
        broker, url, logins = own_broker(args, mats, local, vm)
        started.append(broker)
        background.append(broker.supervise())  # restarted if it dies
        if vm is not None:
            vm.logins = logins
    if vm is not None:
        vm.broker = url
        beds, sides = None, None
        folder = args.virtual_calibrations
        if vm.beds:
            beds = virtual_calibration(folder, "bed", bed_calibration)
            sides = virtual_bed_model(beds.id)
        seat = virtual_calibration(folder, "seat", seat_calibration)
        mats += vm.configs(seat, beds, args.reposition_min, sides, args.turn_every)
        if args.group:  # the mats are devices of their own: a member that dies keeps none
            print(f"texsense station: {args.virtual_mats} virtual mats, published by "
                  "`texsense simulate mats`", flush=True)  # fmt: skip
        else:
            background.append(vm.run_apart())
    if args.group:
        station: Station = group_station(args, url, mats, access.token)
    else:
        station = Station(url, mats, topic=args.mats, store=open_store(args.db),
                          record_dir=args.record_dir, min_stale_s=args.stale_after,
                          refuse_after_s=args.refuse_after)  # fmt: skip
    background += [station.consume(mat_id, src) for mat_id, src in local.items()]
    freeze_built()
    print(f"texsense station: {len(mats)} mats -> {page_url(args, access.token)}", flush=True)
    stopped: int | None = serve_ward(station, host=args.host, port=args.port, access=access,
                                     background=background)  # fmt: skip
    return stopped
