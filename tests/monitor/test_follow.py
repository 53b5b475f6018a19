"""A station behind (issue 38): the frames it skips to keep up are followed through the
pipeline and the exposure without a snapshot (:meth:`texsense.monitor.live.Monitor.follow`),
so its exposure timers, alerts and the pipeline's state (failure detector, Preisach memory,
drift history) are exactly those of a station that processed every frame, whatever frames
it skipped. One virtual seat (its elements fail now and then: the detector's history
matters), fed as `texsense station` feeds it; skip patterns generated."""

from __future__ import annotations

import asyncio
import json
import time
from pathlib import Path

import numpy as np
import pytest

from texsense.calibration.workflows import seat_calibration
from texsense.monitor.store import EventStore
from texsense.monitor.virtual import VirtualSeatSource
from texsense.station.virtual import VirtualMats, frame_payload
from texsense.station.ward import FOLLOW_S, MatEntry, Station

SPEED = 8.0
#: frames of the seat (1.6 s each): the first reposition alert (5 min) comes at ~300 s
FRAMES = 260


@pytest.fixture(scope="module")
def seat():
    """A seat's config, its payloads with their arrival times, and the run that processed
    every frame."""
    config = VirtualMats(1, None, speed=SPEED).configs(seat_calibration(), None, 5.0)[0]
    src = VirtualSeatSource(speed=0, seed=3)

    async def take() -> list[tuple[bytes, float]]:
        out = []
        async for f in src.frames():
            out.append((frame_payload(f), 1000.0 + float(f.element_times[0]) / SPEED))
            if len(out) == FRAMES:
                return out
        return out

    payloads = asyncio.run(take())
    return config, payloads, fed(config, payloads, [False] * FRAMES)


def fed(config, payloads, skims, peek: bool = False) -> MatEntry:
    entry = MatEntry(config, EventStore(":memory:"), Path("recordings-unused"), 1.0)
    for (p, now), skim in zip(payloads, skims, strict=True):
        assert entry.handle(p, now, skim=skim, peek=peek)
    return entry


def patterns() -> dict[str, list[bool]]:
    """Which frames a station skims (True), the last one read: at random (a fifth, most),
    in bursts (a station seconds behind: runs of 2-15), every frame but each fifth."""
    rng = np.random.default_rng(38)
    out = {f"random {p}": list(rng.random(FRAMES) < p) for p in (0.2, 0.7)}
    bursts, k = [False] * FRAMES, 0
    while k < FRAMES:
        run = int(rng.integers(2, 16))
        bursts[k : k + run] = [True] * len(bursts[k : k + run])
        k += run + int(rng.integers(1, 4))
    out["bursts"] = bursts
    out["all but each fifth"] = [k % 5 != 4 for k in range(FRAMES)]
    for v in out.values():
        v[-1] = False
    return out


def events(entry: MatEntry) -> list[tuple[str, float, object]]:
    m = entry.monitor
    return [(e["kind"], e["t"], e["alert"]) for e in m.store.events(m.session_id)]


def alerts(entry: MatEntry) -> list[tuple[float, list[int], float | None]]:
    return [(a.opened_t, a.elements, a.cleared_t) for a in entry.monitor.tracker.alerts]


@pytest.mark.parametrize("name", list(patterns()))
def test_skimmed_frames_give_the_timers_and_alerts_of_every_frame(seat, name):
    config, payloads, whole = seat
    assert whole.monitor.tracker.alerts, "the run has an alert to compare"
    skims = patterns()[name]
    entry = fed(config, payloads, skims)
    assert entry.behind == sum(skims) and entry.peeked == 0
    assert entry.monitor.frames == FRAMES - sum(skims)
    # bit for bit: the exposure of every element, the alerts, the events, the pipeline
    ours, theirs = entry.monitor, whole.monitor
    np.testing.assert_array_equal(ours.tracker.exposure_s, theirs.tracker.exposure_s)
    assert alerts(entry) == alerts(whole)
    assert events(entry) == events(whole)
    assert bytes(entry.monitor.pipeline.snapshot()) == bytes(whole.monitor.pipeline.snapshot())
    np.testing.assert_array_equal(entry.monitor.last_pressure, whole.monitor.last_pressure)
    assert json.dumps(entry.monitor.tracker.state()) == json.dumps(whole.monitor.tracker.state())


def test_a_station_far_behind_peeks_and_says_so(seat):
    """Frames that waited longer than FOLLOW_S are peeked at (their time only): counted as
    such, and the exposure then is not exact (which is why the station follows the others)."""
    config, payloads, whole = seat
    skims = patterns()["random 0.7"]
    entry = fed(config, payloads, skims, peek=True)
    assert entry.peeked == entry.behind == sum(skims)
    off = np.abs(entry.monitor.tracker.exposure_s - whole.monitor.tracker.exposure_s).max()
    assert off > 1.0, off


def test_the_station_peeks_only_at_frames_that_waited_over_follow_s(seat, tmp_path):
    """Station.skip (what the inbox calls for a late frame with newer ones behind it) follows
    a frame that waited up to FOLLOW_S and peeks at one that waited longer."""
    config, payloads, _ = seat
    station = Station(None, [config], record_dir=tmp_path)
    entry = station.mats[config.id]
    topic = f"texsense/{config.id}/frames"
    now = time.time()
    station.handle(topic, payloads[0][0], now - 2 * FOLLOW_S)
    assert station.skip(topic, payloads[1][0], time.time() - FOLLOW_S - 1.0)
    assert (entry.behind, entry.peeked) == (1, 1)
    assert station.skip(topic, payloads[2][0], time.time() - 0.5 * FOLLOW_S)
    assert (entry.behind, entry.peeked, entry.monitor.frames) == (2, 1, 1)
