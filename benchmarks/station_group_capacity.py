"""What a group of stations holds as members are added (issue 38): 1, 2, 3 members of one
group over M mats of 1024 elements at a rate, through a real Mosquitto and a real PostgreSQL.

Run:  .venv/bin/python benchmarks/station_group_capacity.py --members 1,2,3 --loads 200x1,400x1

For each load and number of members, fresh `texsense station --group cap` processes (one per
member, the same ward file of M mats of 32 x 32 elements with the seat's spacer model and
per-element gains, as benchmarks/station_load.py uses) share the mats by rendezvous hashing;
the benchmark waits until every mat is held where the hashing says, then the publisher of
station_load.py sends every mat's frames at the rate (phases spread over the period), each
stamped with its wall-clock send time. Viewers on the dashboards of five mats (``--viewers``;
at the member that holds each) measure frame-to-viewer latency (the p99 and how many samples
were over :data:`LATE_MS`, after the first tenth of them: the start); at the end every member's
`GET /api/mats` says how many frames each mat it holds processed, against how many were
published. The members' CPU is taken over the measuring window (also per frame processed: each
member's CPU over the frames its mats processed in that window, in ms), and the publisher's per
frame sent (its own count of CPU time). One machine: members beyond its cores add
no capacity here (they would on machines of their own).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np
import psycopg

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from archive_scale import big_calibration
from conftest import free_port
from postgres_server import PostgresServer
from station_load import PUBLISHER, cpu_seconds, receive, viewer
from texsense.station.broker import Broker
from texsense.station.lease import preferred
from texsense.station.workers import worker_name

#: A sample later than this counts as late in the row, ms (issue 38's target is p99 < 100 ms).
LATE_MS = 100.0


def get(url: str, timeout: float = 30.0):
    with urllib.request.urlopen(url, timeout=timeout) as r:
        return json.load(r)


def start_members(tmp: Path, broker: Broker, db: str, ward: Path, names: list[str],
                  workers: int = 1, probe: Path | None = None, own_session: bool = False,
                  ) -> dict:  # fmt: skip
    """The members' processes and their group members' (name, page URL): one each, or its
    workers' with ``--workers`` (ports PORT..PORT+W-1); started together. ``probe``: each
    member's event loop timed by :mod:`loop_probe`, its long callbacks written to
    ``probe/<member>.tsv``. ``own_session``: each member in a session of its own (as a
    service or a terminal of its own would start it; Linux's autogroups share the CPU between
    sessions first, see ``--session``)."""
    out = {}
    for name in names:
        port = free_port() if workers == 1 else free_ports(workers)
        log = (tmp / f"{name}.log").open("wb")
        more = ["--workers", str(workers)] if workers > 1 else []
        start = ["-m", "texsense.cli"]
        if probe is not None:
            start = ["-c", f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
                     f"import loop_probe; loop_probe.run_module('texsense.cli', "
                     f"{str(probe / f'{name}.tsv')!r})"]  # fmt: skip
        proc = subprocess.Popen(
            [sys.executable, *start, "station", "--group", "cap", "--member", name,
             "--config", str(ward), "--broker", f"mqtt://127.0.0.1:{broker.port}", "--db", db,
             "--port", str(port), "--record-dir", str(tmp / f"rec-{name}"), *more],
            stdout=log, stderr=subprocess.STDOUT, start_new_session=own_session,
        )  # fmt: skip
        parts = [(name, port)] if workers == 1 else [
            (worker_name(name, k), port + k) for k in range(workers)]  # fmt: skip
        out[name] = (proc, [(w, f"http://127.0.0.1:{p}/") for w, p in parts])
    return out


def free_ports(n: int) -> int:
    """The first of ``n`` consecutive free ports."""
    for _ in range(100):
        first = free_port()
        if all(port_free(first + k) for k in range(1, n)):
            return first
    raise SystemExit(f"no {n} consecutive free ports")


def port_free(port: int) -> bool:
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def tree_cpu(pid: int) -> float:
    """CPU seconds of a process and its children (a member's workers)."""
    kids = Path(f"/proc/{pid}/task/{pid}/children")
    children = [int(c) for c in kids.read_text().split()] if kids.exists() else []
    return cpu_seconds(pid) + sum(tree_cpu(c) for c in children)


def settle(members: dict, mats: list[str], timeout: float = 600.0) -> float:
    """Wait until every mat is held by the group member rendezvous hashing names; seconds
    taken."""
    names = sorted(w for _, parts in members.values() for w, _ in parts)
    want = {m: preferred(m, names) for m in mats}
    first = next(iter(members.values()))[1][0][1]
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        for name, (proc, _) in members.items():
            if proc.poll() is not None:
                raise SystemExit(f"member {name} exited: see its log")
        try:
            rows = get(first + "api/mats", timeout=10)
            if {r["id"]: r.get("holder") for r in rows} == want:
                return time.monotonic() - t0
        except OSError:
            pass
        time.sleep(0.5)
    raise SystemExit(f"the group did not settle in {timeout:.0f} s")


def run(tmp: Path, broker: Broker, pg: PostgresServer, n: int, mats: int, hz: float,
        seconds: float, db_k: int, workers: int = 1, probe: Path | None = None,
        dump: Path | None = None, viewers: int = 5, own_session: bool = False,
        ) -> dict:  # fmt: skip
    ward = tmp / f"ward-{mats}.toml"
    ward.write_text("".join(
        f'[[mat]]\nid = "m{m:03d}"\nlayout = "grid:32x32"\ncalibration = "{tmp / "cal.json"}"\n\n'
        for m in range(mats)
    ))  # fmt: skip
    db = f"cap{db_k}"
    with psycopg.connect(pg.url, autocommit=True) as c:
        c.execute(f"CREATE DATABASE {db}")
    url = pg.url.rsplit("/", 1)[0] + "/" + db
    ids = [f"m{m:03d}" for m in range(mats)]
    names = [f"s{k + 1}" for k in range(n)]
    members = start_members(tmp, broker, url, ward, names, workers, probe, own_session)
    try:
        took = settle(members, ids)
        first = next(iter(members.values()))[1][0][1]
        holder = {r["id"]: r["holder_url"] for r in get(first + "api/mats")}
        pub = subprocess.Popen(
            [sys.executable, "-c", PUBLISHER, str(broker.port), str(mats), str(hz),
             str(seconds), str(tmp / "cal.npz")],
            stdout=subprocess.PIPE, text=True,
        )  # fmt: skip
        start = time.time()
        stop = start + seconds
        watched = [ids[k] for k in np.linspace(0, mats - 1, min(viewers, mats)).astype(int)]
        latencies: list[float] = []
        cpu: dict[str, float] = {}
        per_frame: dict[str, float] = {}

        def frames_of(name: str) -> int:  # of every group member (worker) it runs
            return sum(r["frames"] for w, page in members[name][1] for r in get(page + "api/mats")
                       if r["holder"] == w)  # fmt: skip

        async def members_cpu() -> None:
            await asyncio.sleep(5.0)
            t0 = time.time()
            c0 = {k: tree_cpu(p.pid) for k, (p, _) in members.items()}
            f0 = {k: await asyncio.to_thread(frames_of, k) for k in members}
            await asyncio.sleep(max(stop - time.time(), 0.0))
            for k, (p, _) in members.items():
                used = tree_cpu(p.pid) - c0[k]
                cpu[k] = used / (time.time() - t0)
                done = await asyncio.to_thread(frames_of, k) - f0[k]
                per_frame[k] = 1e3 * used / max(done, 1)

        samples: list[str] = []

        def seen(w: str, text: str) -> None:  # a viewer's sample, kept for --dump
            now, snap = time.time(), json.loads(text)
            latencies.append(now - snap["t"])
            samples.append(json.dumps({"mat": w, "viewer": now, "t": snap["t"],
                                       "received_at": snap.get("received_at"),
                                       "processed_ms": snap.get("processed_ms")}))  # fmt: skip

        async def view(w: str) -> None:
            url = holder[w].replace("http", "ws", 1) + f"mats/{w}/ws"
            try:
                if dump is None:
                    await viewer(url, latencies, stop)
                else:
                    await receive(url, stop, lambda text: seen(w, text))
            except Exception as e:  # said, and the row goes on with the other viewers
                print(f"viewer of {w} at {url}: {type(e).__name__}: {e}", file=sys.stderr)

        async def view_all() -> None:
            await asyncio.gather(*(view(w) for w in watched), members_cpu())

        asyncio.run(view_all())
        sent = json.loads(pub.communicate(timeout=120)[0])
        if dump is not None:
            dump.write_text("\n".join(samples) + "\n")
        time.sleep(1.0)  # the members drain what is in flight
        processed = sum(frames_of(name) for name in members)
        lat = np.asarray(latencies[len(latencies) // 10 :]) * 1e3  # after the start
        return {
            "members": n, "mats": mats, "hz": hz, "settle_s": took, "sent": sent["sent"],
            "processed": processed, "lost": sent["sent"] - processed,
            "p50": float(np.percentile(lat, 50)) if lat.size else float("nan"),
            "p99": float(np.percentile(lat, 99)) if lat.size else float("nan"),
            "samples": int(lat.size), "late": int(np.sum(lat > LATE_MS)),
            "cpu": " / ".join(f"{100 * cpu[k]:.0f}" for k in sorted(cpu)),
            "ms_frame": " / ".join(f"{per_frame[k]:.2f}" for k in sorted(per_frame)),
            "pub_us": sent["cpu_us_per_frame"],
        }  # fmt: skip
    finally:
        for proc, _ in members.values():
            if workers > 1:  # the supervisor stops its workers (and reaps them)
                proc.terminate()
            else:
                proc.kill()
        for proc, _ in members.values():
            try:
                proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", default="1,2,3")
    ap.add_argument("--loads", default="200x1,400x1", help="MATSxHZ,...")
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument(
        "--workers",
        type=int,
        default=1,
        help="each member as W worker processes (texsense station --workers W)",
    )
    ap.add_argument(
        "--viewers", type=int, default=5, help="dashboards watched (each a mat), default 5"
    )
    ap.add_argument(
        "--session",
        choices=("shared", "own"),
        default="shared",
        help="the members in the benchmark's session (with its publisher, broker and viewers) "
        "or each in its own: with Linux's autogroup scheduling (/proc/sys/kernel/"
        "sched_autogroup_enabled) the CPU is shared between sessions first",
    )
    ap.add_argument(
        "--probe",
        type=Path,
        help="a folder: each member's long event-loop callbacks (loop_probe.py)",
    )
    ap.add_argument(
        "--dump", type=Path, help="a folder: every viewer's sample of each row (JSON lines)"
    )
    args = ap.parse_args()
    for folder in (args.probe, args.dump):
        if folder is not None:
            folder.mkdir(parents=True, exist_ok=True)
    counts = [int(v) for v in args.members.split(",")]
    loads = [(int(m), float(h)) for m, h in (x.split("x") for x in args.loads.split(","))]
    where = "their own sessions" if args.session == "own" else "the benchmark's session"
    print(f"load average {os.getloadavg()[0]:.1f} at the start (2 cores, shared); members in "
          f"{where}")  # fmt: skip
    print(
        "| mats (1024 elements) | rate | members | settled after | frames published | "
        "processed | lost | frame-to-viewer p50 | p99 | samples | over 100 ms | "
        "members' CPU (% of a core) | "
        "members' CPU per frame processed (ms) | publisher's CPU per frame (µs) |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|---:|")
    with tempfile.TemporaryDirectory() as d, Broker() as broker:
        tmp = Path(d)
        cal = big_calibration(1024, tmp / "cal.json")
        c = cal["convert"]
        np.savez(tmp / "cal.npz", offset=c.offset_pF_, gain=c.gain_,
                 curve_e=c.curve_compression_mm_, curve_c=c.curve_capacitance_pF_)  # fmt: skip
        pg = PostgresServer()
        try:
            k = 0
            for mats, hz in loads:
                for n in counts:
                    k += 1
                    dump = args.dump / f"row{k}.jsonl" if args.dump else None
                    probe = args.probe / f"row{k}" if args.probe else None
                    if probe is not None:
                        probe.mkdir(exist_ok=True)
                    r = run(tmp, broker, pg, n, mats, hz, args.seconds, k, args.workers, probe,
                            dump, args.viewers, args.session == "own")  # fmt: skip
                    print(f"| {mats} | {hz:g} Hz | {n} | {r['settle_s']:.0f} s | {r['sent']} | "
                          f"{r['processed']} | {r['lost']} | {r['p50']:.0f} ms | "
                          f"{r['p99']:.0f} ms | {r['samples']} | {r['late']} | {r['cpu']} | "
                          f"{r['ms_frame']} | "
                          f"{r['pub_us']:.0f} |", flush=True)  # fmt: skip
        finally:
            pg.close()
    print(f"load average {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
