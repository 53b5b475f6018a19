"""``texsense simulate PROTOCOL``: run a test-machine protocol on the virtual sensor;
``texsense seat-sessions``: capacitance sessions of the virtual seat with its calibration."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import itertools
import os
import signal
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np

from texsense._progress import progress
from texsense.calibration.night import night_calibration
from texsense.calibration.workflows import seat_calibration
from texsense.commands import HELP
from texsense.commands._applies import Rule, only_where
from texsense.data.files import check_not_input, make_folder, real_path
from texsense.exceptions import ParameterError
from texsense.io import save
from texsense.io.columns_csv import write_columns_csv
from texsense.sensor.materials import PRESETS
from texsense.sim.device import VirtualDevice
from texsense.sim.night import virtual_night
from texsense.sim.protocols import PROTOCOLS, run_protocol
from texsense.sim.seated import Subject, simulate_session
from texsense.station.broker import parse_broker_url
from texsense.station.virtual import VirtualMats

#: CLI option -> protocol keyword, for the protocols that take it.
_OPTIONS = {
    "speed": "speed_mm_min",
    "max": "max_ncm2",
    "cycles": "cycles",
    "hold": "hold_s",
    "levels": "levels",
    "falling": "falling",
    "p3": "p3_ncm2",
    "duration": "duration_s",
}
_ACCEPTS = {
    "ramp": {"max", "speed", "cycles"},
    "calibration": {"max", "speed"},
    "validation": {"cycles", "speed"},
    "steps": {"levels", "hold", "speed", "falling"},
    "loads": {"levels", "hold", "speed"},
    "cyclic": {"p3", "duration", "speed"},
    "random": {"duration", "max"},
    "sawtooth": {"max", "speed"},
}


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``simulate`` command."""
    p = sub.add_parser(
        "simulate",
        help=HELP["simulate"],
        description="Simulate a spacer specimen on a test machine and read it out through an "
        "electrode and an AD7745-class converter. The HDF5 output holds the measured "
        "capacitance with the true pressure and compression as labels; the CSV holds "
        "time_s,compression_mm,pressure_ncm2,capacitance_pF.",
    )
    p.add_argument(
        "protocol",
        choices=[*sorted(PROTOCOLS), "device", "night", "mats"],
        help="protocol to run; 'device': a virtual mat behind a serial line (--mat, --link); "
        "'night': a person's night on the virtual bed mat (--hours, --truth, --calibration); "
        "'mats': virtual mats publishing to a broker (--count, --broker)",
    )
    p.add_argument(
        "--spacer",
        choices=sorted(PRESETS),
        help="spacer preset (default textile-6mm; a night: textile-3mm, the bed mat's)",
    )
    p.add_argument("--seed", type=int, default=0, help="specimen and noise seed (default 0)")
    p.add_argument("-o", "--output", type=Path, help="HDF5 file to write")
    p.add_argument("--csv", type=Path, help="CSV file to write")
    p.add_argument("--sample-hz", type=float, default=10.0, help="output rate (default 10 Hz)")
    p.add_argument(
        "--speed", type=float, help="platen speed, mm/min (device: times faster than real time)"
    )
    p.add_argument("--max", type=float, help="maximal pressure, N/cm²")
    p.add_argument("--cycles", type=int, help="number of cycles")
    p.add_argument("--hold", type=float, help="hold time per step or load, s")
    p.add_argument(
        "--levels",
        type=lambda s: tuple(float(v) for v in s.split(",")),
        help="step levels, N/cm² (comma separated)",
    )
    p.add_argument("--falling", action="store_true", help="falling steps (from 10 N/cm²)")
    p.add_argument("--p3", type=float, help="upper pressure of cyclic compression, N/cm²")
    p.add_argument("--duration", type=float, help="duration, s")
    device = p.add_argument_group("device (texsense simulate device --mat seat --link PATH)")
    device.add_argument("--mat", default="seat", help="device: seat (96 elements) or bed (2048)")
    device.add_argument("--link", type=Path, help="device: the serial port's path to create")
    device.add_argument(
        "--load", default="empty", help="device: empty | uniform:P (N/cm²) | person"
    )
    device.add_argument(
        "--failures", action="store_true", help="device: elements fail at the thesis's rates"
    )
    device.add_argument(
        "--truth", type=Path, help="device, night: the true pressure of every frame (HDF5)"
    )
    night = p.add_argument_group("night (texsense simulate night -o night.h5 --truth truth.h5)")
    night.add_argument("--hours", type=float, default=8.0, help="night: its length (8 h)")
    night.add_argument(
        "--calibration",
        type=Path,
        help="night: write the mat's calibration (zero, 1 N/cm², the spacer's preset) here",
    )
    mats = p.add_argument_group("mats (texsense simulate mats --count N --broker URL): the "
                                "virtual mats of `texsense station --virtual-mats N`")  # fmt: skip
    mats.add_argument("--count", type=int, default=10, help="mats: how many (default 10)")
    mats.add_argument("--broker", help="mats: mqtt://[user[:password]@]host[:port] (or the "
                      "password in $TEXSENSE_BROKER_PASSWORD)")  # fmt: skip
    mats.add_argument("--prefix", default="texsense", help="mats: topic prefix (default texsense)")
    mats.add_argument("--beds", type=int, metavar="K", help="mats: only the first K "
                      "even-numbered mats are beds (default: every second one)")  # fmt: skip
    p.set_defaults(run=run)
    only_where(p, [Rule(flag, _protocol_in(modes), "simulate " + ", ".join(sorted(modes)))
                   for flag, modes in _simulate_modes().items()])  # fmt: skip
    register_sessions(sub)


#: The modes of ``simulate`` besides the test-machine protocols.
_OTHERS = ("device", "mats", "night")


def _simulate_modes() -> dict[str, set[str]]:
    """Every option of ``simulate`` -> the protocols and modes it does something in."""
    protocols = set(_ACCEPTS)
    modes = {f"--{flag}": {p for p, takes in _ACCEPTS.items() if flag in takes}
             for flag in _OPTIONS}  # fmt: skip
    modes["--speed"] |= {"device", "mats"}
    modes.update({
        "--spacer": protocols | {"night"}, "--seed": protocols | {"device", "night"},
        "--output": protocols | {"night"}, "--csv": set(protocols),
        "--sample-hz": set(protocols), "--truth": {"device", "night"},
        **{f: {"device"} for f in ("--mat", "--link", "--load", "--failures")},
        **{f: {"night"} for f in ("--hours", "--calibration")},
        **{f: {"mats"} for f in ("--count", "--broker", "--prefix", "--beds")},
    })  # fmt: skip
    return modes


def _protocol_in(modes: set[str]) -> Any:
    return lambda args: args.protocol in modes


def run(args: argparse.Namespace) -> int:
    """Run ``texsense simulate``."""
    if args.protocol == "device":
        return run_device(args)
    if args.protocol == "mats":
        return run_mats(args)
    if args.protocol == "night":
        return run_night(args)
    args.spacer = args.spacer or "textile-6mm"
    if args.output is None and args.csv is None:
        raise ParameterError("give an output: -o FILE.h5 and/or --csv FILE.csv")
    if args.output and args.csv and real_path(args.output) == real_path(args.csv):
        raise ParameterError(f"-o and --csv name the same file {args.output}")
    options: dict[str, Any] = {}
    for flag, keyword in _OPTIONS.items():
        value = getattr(args, flag)
        if value not in (None, False):  # (given elsewhere: refused, _simulate_modes)
            options[keyword] = value
    rec = run_protocol(
        args.protocol, args.spacer, seed=args.seed, sample_hz=args.sample_hz, **options
    )
    if args.output:
        rec.save(args.output)
        print(f"wrote {args.output}")
    if args.csv:
        write_columns_csv(
            args.csv,
            {
                "time_s": rec.times,
                "compression_mm": rec.labels["compression_mm"],
                "pressure_ncm2": rec.labels["pressure_ncm2"],
                "capacitance_pF": rec.frames[:, 0],
            },
        )
        print(f"wrote {args.csv}")
    p = rec.labels["pressure_ncm2"]
    print(
        f"{args.protocol} on {args.spacer} (seed {args.seed}): {rec.n_frames} samples over "
        f"{rec.duration_s:.6g} s, pressure 0-{p.max():.3g} N/cm², capacitance "
        f"{rec.frames.min():.3f}-{rec.frames.max():.3f} pF"
    )
    return 0


def run_device(args: argparse.Namespace) -> int:
    """Run ``texsense simulate device``: serve until Ctrl-C or SIGTERM."""

    if args.link is None:
        raise ParameterError("simulate device needs --link PATH (the serial port to create)")
    if args.output or args.csv:
        raise ParameterError("simulate device writes no -o/--csv: use --truth FILE.h5")
    device = VirtualDevice(
        args.mat,
        load=args.load,
        seed=args.seed,
        failures=args.failures,
        speed=1.0 if args.speed is None else args.speed,
    )
    info = device.info()
    print(
        f"texsense simulate device: virtual {info['mat']} ({info['elements']} elements, "
        f"{info['grid']} grid, spacer {info['spacer']}, a frame every {info['frame_s']:.3g} s, "
        f"load {info['load']}) on {args.link}; type a load (empty, uniform:P, person) and "
        "Enter to change it; Ctrl-C stops",
        flush=True,
    )
    threading.Thread(target=_loads_from_stdin, args=(device,), daemon=True).start()
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    device.serve(args.link, stop=stop, truth=args.truth)
    print(
        f"texsense simulate device: stopped after {device.frames_sent} frames "
        f"({device.dropped} dropped: no reader)",
        flush=True,
    )
    return 0


def run_mats(args: argparse.Namespace) -> int:
    """Run ``texsense simulate mats``: publish until Ctrl-C or SIGTERM."""
    if not args.broker:
        raise ParameterError("simulate mats needs --broker mqtt://host[:port]")
    if args.count < 1:
        raise ParameterError(f"--count must be >= 1, got {args.count}")
    broker = parse_broker_url(args.broker)
    if broker.password is None and os.environ.get("TEXSENSE_BROKER_PASSWORD"):
        broker = broker.login(broker.username or "", os.environ["TEXSENSE_BROKER_PASSWORD"])
    speed = 1.0 if args.speed is None else args.speed
    mats = VirtualMats(args.count, broker, prefix=args.prefix, speed=speed, beds=args.beds)
    print(f"texsense simulate mats: {args.count} virtual mats ({mats.ids[0]} ...) publish to "
          f"{broker} under {mats.prefix}/ at {speed:g}x; Ctrl-C stops", flush=True)  # fmt: skip

    async def publish() -> None:
        task = asyncio.ensure_future(mats.run())
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, task.cancel)
        with contextlib.suppress(asyncio.CancelledError):
            await task

    asyncio.run(publish())
    print(f"texsense simulate mats: stopped after {mats.published} frames", flush=True)
    return 0


def run_night(args: argparse.Namespace) -> int:
    """Run ``texsense simulate night``: the raw night, its truth and the mat's calibration."""

    if args.output is None:
        raise ParameterError("simulate night needs -o NIGHT.h5 (the raw capacitance)")
    if args.csv is not None:
        raise ParameterError("simulate night writes recordings: -o, --truth, --calibration")
    outputs = [p for p in (args.output, args.truth, args.calibration) if p is not None]
    if len({p.resolve() for p in outputs}) < len(outputs):
        raise ParameterError("-o, --truth and --calibration must name different files")
    spacer = args.spacer or "textile-3mm"
    for path in outputs:
        check_not_input(path, [])
    night = virtual_night(spacer, args.hours, args.seed)
    save(night.raw, args.output)
    print(f"wrote {args.output}")
    if args.truth is not None:
        save(night.truth, args.truth)
        print(f"wrote {args.truth}")
    if args.calibration is not None:
        chain = night_calibration(spacer)
        chain.save(args.calibration)
        print(f"wrote {args.calibration}")
    sides = night.truth.labels["side"]
    turns = night_turns(sides)
    outs = int(np.count_nonzero((sides[1:] == "out") & (sides[:-1] != "out")))
    print(
        f"night of {night.sleeper.name} ({night.sleeper.weight_kg:.0f} kg) on the {spacer} bed "
        f"mat: {night.raw.n_frames} frames over {args.hours:g} h, empty at first, "
        f"{turns} turn{'' if turns == 1 else 's'}, out of bed {_times(outs)}"
    )
    return 0


def night_turns(sides: np.ndarray) -> int:
    """Turns in a night's side labels: a side in bed followed by another side in bed (the
    transitions between them skipped); getting into bed or out of it is not a turn (it
    counted every transition: "1 turn" for a night whose person only got into bed)."""
    held = [str(s) for s in sides if str(s) != "transition"]
    runs = [s for k, s in enumerate(held) if k == 0 or s != held[k - 1]]
    return sum(1 for a, b in itertools.pairwise(runs) if "out" not in (a, b))


def _times(n: int) -> str:
    """never, once, twice, 3 times."""
    return {0: "never", 1: "once", 2: "twice"}.get(n, f"{n} times")


def _loads_from_stdin(device: VirtualDevice) -> None:
    """Change the device's load for every line typed on standard input (ends at its end)."""
    for line in sys.stdin:
        text = line.strip()
        if not text:
            continue
        try:
            device.set_load(text)
        except ParameterError as e:
            print(f"texsense simulate device: {e}", file=sys.stderr, flush=True)
            continue
        print(f"texsense simulate device: load {text} from frame {device.frames_sent}", flush=True)


def register_sessions(sub: argparse._SubParsersAction) -> None:
    """Add the ``seat-sessions`` command."""
    p = sub.add_parser(
        "seat-sessions",
        help=HELP["seat-sessions"],
        description="Simulate subjects' sessions on the 96-element virtual seat (thesis §6.2: "
        "the 16 postures in rounds, with the thesis's failure rates) and write each as a "
        "capacitance recording (session-NNN.h5), with the seat's calibration "
        "(calibration.json, made as a user would: zeroing, 1 N/cm² equilibration, spacer "
        "model and drift from another specimen's test-machine records). Input for "
        "'texsense process' on an archive.",
    )
    p.add_argument("-n", "--sessions", type=int, default=4, help="number of sessions")
    p.add_argument("--rounds", type=int, default=1, help="posture rounds per session")
    p.add_argument("--rest-s", type=float, default=60.0,
                   help="unloaded rest before the third round (--rounds 3 or more)")  # fmt: skip
    p.add_argument("--mat-seed", type=int, default=5, help="the physical mat (same for all)")
    p.add_argument("-o", "--output", type=Path, required=True, help="folder to write")
    p.set_defaults(run=run_sessions)
    only_where(p, [Rule("--rest-s", lambda a: a.rounds >= 3, "three rounds or more (--rounds 3: "
                        "the rest comes before the third)")])  # fmt: skip


def run_sessions(args: argparse.Namespace) -> int:
    """Run ``texsense seat-sessions``."""

    if args.sessions < 1 or args.rounds < 1 or args.rest_s < 0:
        raise ParameterError("--sessions and --rounds must be >= 1 and --rest-s >= 0")
    make_folder(args.output)
    cal = seat_calibration(mat_seed=args.mat_seed)
    cal.save(args.output / "calibration.json")
    frames = 0
    for k in progress(range(args.sessions), total=args.sessions, desc="sessions", unit="file"):
        s = simulate_session(
            Subject.random(k), mat_seed=args.mat_seed, rounds=args.rounds, rest_s=args.rest_s
        )
        save(s.capacitance, args.output / f"session-{k + 1:03d}.h5")
        frames += s.capacitance.n_frames
    print(
        f"wrote {args.sessions} sessions ({frames} frames of 96 elements) and "
        f"calibration.json (id {cal.id}) to {args.output}"
    )
    return 0
