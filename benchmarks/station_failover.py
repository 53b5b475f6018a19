"""What a takeover costs in a group of stations: a member is killed (SIGKILL), how long until
the others hold and read its mats, and what of them is lost.

Run:  .venv/bin/python benchmarks/station_failover.py [--members 3 --mats 60 --kills 3]

A real PostgreSQL, a real Mosquitto, `texsense simulate mats` publishing ``--mats`` virtual
mats at ``--speed`` (a frame per 1.6 simulated s), ``--members`` members of the group
``ward`` and a reference station in a group of its own (its own database) that reads the
same frames and is never killed. Each round kills one member (in turn), times until every mat
it held is held by another member and has read a frame after the kill, and then compares
with the reference, at the same moment, per moved mat: the frames that count in the mat's
state (frames lost: read by the reference, not by the group: those after the victim's last
checkpoint and those published while nobody held the mat) and the exposure timer. The member
is started again after each round and the group settles before the next.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from group_cluster import Cluster


def one_kill(c: Cluster, victim: str, watcher: str) -> dict[str, float]:
    before = c.all_held(watcher)
    moved = sorted(k for k, m in before.items() if m["holder"] == victim)
    t0 = time.monotonic()
    c.kill(victim)
    live = ("live", "alert", "acknowledged")

    def back(s: dict) -> bool:
        return all(s[k]["holder"] not in (None, victim) and s[k]["state"] in live
                   and s[k]["frames"] > before[k]["frames"] for k in moved)  # fmt: skip

    c.until(lambda: c.mats_of(watcher), back, 60, step=0.05)
    took = time.monotonic() - t0
    time.sleep(3.0)  # a few frames more on both sides, then read both at once
    ours, ref = c.mats_of(watcher), c.mats_of("ref")
    lost = np.array([ref[k]["frames"] - ours[k]["frames"] for k in moved], float)
    off = np.array([abs(ref[k]["minutes_since_reposition"] -
                        ours[k]["minutes_since_reposition"]) * 60 for k in moved])  # fmt: skip
    c.start(victim)
    return {"mats": len(moved), "took": took, "lost_mean": float(lost.mean()),
            "lost_max": float(lost.max()), "off_max": float(off.max())}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--members", type=int, default=3)
    ap.add_argument("--mats", type=int, default=60)
    ap.add_argument("--kills", type=int, default=3)
    ap.add_argument("--speed", type=float, default=4.0)
    args = ap.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="texsense-failover-", dir="/tmp"))
    folder.chmod(0o755)
    names = [chr(ord("a") + k) for k in range(args.members)]
    c = Cluster(folder, names, args.mats, speed=args.speed)
    rows = []
    try:
        c.start("ref", group="ref", db=c.database("reference"))
        c.all_held("ref", timeout=600)  # the stations start (calibrations)
        for k in range(args.kills):
            victim = names[(k + 1) % len(names)]
            c.all_held(names[0], timeout=120)
            # every member holds a share (one that came back takes it after 10 s)
            c.until(lambda: c.mats_of(names[0]),
                    lambda s: all(any(m["holder"] == n for m in s.values()) for n in names),
                    120)  # fmt: skip
            rows.append(one_kill(c, victim, names[0] if victim != names[0] else names[1]))
            print(f"kill {k + 1}: {rows[-1]}", flush=True)
    finally:
        c.close()
    sim = 1.6  # simulated s between a mat's frames
    print(f"\n{args.members} members, {args.mats} mats, {args.speed:g}x "
          "(a frame per 1.6 simulated s); SIGKILL of one member per row\n")  # fmt: skip
    print("| kill | mats moved | all back after (s) | frames lost per mat, mean / max "
          "| = simulated s | timer vs reference, max (s) |")  # fmt: skip
    print("|---:|---:|---:|---:|---:|---:|")
    for k, r in enumerate(rows, 1):
        print(f"| {k} | {r['mats']} | {r['took']:.1f} | {r['lost_mean']:.1f} / "
              f"{r['lost_max']:.0f} | {r['lost_mean'] * sim:.0f} / {r['lost_max'] * sim:.0f} "
              f"| {r['off_max']:.1f} |")  # fmt: skip


if __name__ == "__main__":
    main()
