"""A cheap publisher of virtual seats for the group's fault test (tests/group_cluster.py):
``texsense simulate mats`` runs the virtual sensor for every frame of every mat (~3 ms of a
core a seat frame: its spacer law, hysteresis, failures), which at 60 mats was most of the
test's CPU. Here a few simulated people (``POOL_PEOPLE``, the same
:class:`~texsense.monitor.virtual.VirtualSeatSource` as there) are simulated once for
``POOL_FRAMES`` frames each, their values' JSON made once, and every mat ``vmat-NN`` replays
one of them (mat k: person k mod POOL_PEOPLE, starting ``k // POOL_PEOPLE`` x 37 frames in),
looping, on a time line of its own that goes on (seq and t grow), paced at ``speed`` and
published to the broker as the simulator does (reconnecting when it restarts). With
``EVERY`` > 1 each mat publishes every EVERY-th frame only (a mat that scans every
1.6 x EVERY s): the stations read a 1/EVERY of the frames for the same simulated time (the
group's fault test: the reference's first alert comes after 5 simulated minutes).

Run: python tests/replay_mats.py BROKER_PORT MATS SPEED [EVERY]
"""

from __future__ import annotations

import asyncio
import json
import math
import signal
import sys
import time

from texsense.monitor.virtual import VirtualSeatSource
from texsense.station.broker import BrokerURL, mqtt_client

#: Simulated people whose frames the mats replay.
POOL_PEOPLE = 3
#: Frames of each (at 1.6 s a frame: 8 minutes of sitting, longer than the 5 minutes after
#: which the test's first reposition alert comes).
POOL_FRAMES = 300


def pool(seed: int) -> tuple[list[str], float, float]:
    """One person's frames as the JSON text of their values, the frame period and the
    element step (s)."""
    source = VirtualSeatSource(speed=0, seed=seed)

    async def take() -> list:
        out = []
        async for frame in source.frames():
            out.append(frame)
            if len(out) == POOL_FRAMES:
                return out
        return out

    frames = asyncio.run(take())
    texts = [json.dumps([round(float(v), 5) if math.isfinite(v) else None for v in f.values])
             for f in frames]  # fmt: skip
    times = frames[0].element_times
    return texts, frames[1].t - frames[0].t, float(times[1] - times[0])


def main() -> None:
    port, mats, speed = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
    every = int(sys.argv[4]) if len(sys.argv) > 4 else 1
    people = [pool(seed) for seed in range(min(POOL_PEOPLE, mats))]
    period = people[0][1] * every
    client = mqtt_client(BrokerURL("127.0.0.1", port), f"texsense-replay-{port}")
    client.loop_start()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    start, k = time.monotonic(), 0
    while True:
        delay = start + k * period / speed - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        for m in range(mats):
            texts, _, dt = people[m % len(people)]
            values = texts[(k * every + 37 * (m // len(people))) % len(texts)]
            head = f'{{"seq":{k},"t":{k * period:.6f},"dt":{dt:.9f},"values":'
            payload = head + values + ',"unit":"pF"}'
            client.publish(f"texsense/vmat-{m + 1:02d}/frames", payload)
        k += 1


if __name__ == "__main__":
    main()
