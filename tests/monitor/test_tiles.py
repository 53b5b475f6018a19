"""The ward WebSocket's feed (docs/station.md): downsampled, quantised tiles; only what changed;
within a byte budget per viewer, without starving any mat."""

from __future__ import annotations

import base64
import json

import numpy as np

from texsense import Layout
from texsense.data.protocol import Frame
from texsense.station.tiles import NO_ELEMENT, NO_READING, BlockMap, WardFeed
from texsense.station.ward import MatConfig, Station


def decode(tile: dict) -> np.ndarray:
    return np.frombuffer(base64.b64decode(tile["b64"]), np.uint8).reshape(tile["rows"], -1)


def test_a_bed_is_reduced_to_its_block_peaks():
    lay = Layout.grid(64, 32)
    p = np.zeros(2048)
    p[5 * 32 + 7] = 2.0  # one peak (150 mmHg), in block (1, 2) of 3 x 3 elements
    p[40 * 32 + 20] = np.nan  # a failed element in an otherwise empty block
    tile = BlockMap(lay).encode(p)
    q = decode(tile)
    assert q.shape == (22, 11) and tile["unit"] == "mmHg"
    assert q[1, 2] == 150 and q[13, 6] == 0  # the peak survives; the NaN is one of nine
    assert np.count_nonzero(q) == 1 and not np.any(q == NO_READING)
    p[0] = 5.0  # 375 mmHg: the top of the range
    assert decode(BlockMap(lay).encode(p))[0, 0] == 250
    grid = p.reshape(64, 32)
    grid[39:42, 18:21] = np.nan  # a whole block without a reading
    q = decode(BlockMap(lay).encode(grid.ravel()))
    assert q[13, 6] == NO_READING


def test_a_checkerboard_seat_keeps_its_empty_cells():
    from texsense.sim.mat import VirtualMat

    lay = VirtualMat.seat(seed=5).layout  # 96 of 240 cells
    q = decode(BlockMap(lay).encode(np.full(96, 0.2)))
    assert q.shape == (15, 16) and np.count_nonzero(q != NO_ELEMENT) == 96
    assert set(np.unique(q[q != NO_ELEMENT])) == {15}  # 0.2 N/cm² = 15 mmHg


def ward(n: int) -> Station:
    mats = [MatConfig(f"m{k:03d}", Layout.grid(32, 32), quantity="pressure") for k in range(n)]
    return Station(None, mats)


def test_the_feed_sends_what_changed_within_its_budget_and_starves_nobody():
    st = ward(100)
    rng = np.random.default_rng(0)
    budget = 40_000  # bytes/s: about 50 tiles a second, for 100 mats changing every second
    feed = WardFeed(st, max_bytes_per_s=budget)
    first = feed.message(now=0.0)
    assert json.loads(first)["reset"] and len(first) <= budget
    clock, sizes = 0.0, []
    for second in range(5):  # 100 mats at 1 Hz for 5 s: a feed message every 0.2 s
        for tick in range(5):
            for k in range(tick * 20, (tick + 1) * 20):
                frame = Frame(second, np.full(1024, float(second)), rng.uniform(0, 2, 1024))
                frame.unit = "N/cm2"
                st.mats[f"m{k:03d}"].feed(frame, clock)
            clock += 0.2
            sizes.append(len(feed.message(now=clock)))
    assert sum(sizes) / 5.0 <= 1.05 * budget, sizes
    # the frames stop: within a few seconds every mat's latest state has been sent
    for _ in range(20):
        clock += 0.2
        feed.message(now=clock)
    assert all(feed.sent[e.id] == e.revision for e in st.mats.values())
    # (the last message, a tile or a heartbeat, went out at feed.last: the next is due a
    # second after it, wherever the 0.2 s ticks fell)
    clock = feed.last + 0.5
    assert feed.message(now=clock) is None  # nothing changed: nothing to say ...
    clock += 0.5
    beat = json.loads(feed.message(now=clock))  # ... but a heartbeat a second
    assert beat["mats"] == [] and not beat["reset"]
    st.mats["m007"].feed(Frame(5, np.full(1024, 5.0), np.ones(1024), "N/cm2"), clock)
    one = json.loads(feed.message(now=clock + 1.2))
    assert [m["id"] for m in one["mats"]] == ["m007"] and one["mats"][0]["frames"] == 6


def test_the_ward_page_comes_with_its_tiles_and_nothing_in_them_ends_the_block():
    """``GET /`` carries the feed's first message (the page draws it before its WebSocket
    answers: issue 33); a payload's text in a tile's error cannot close the data block."""
    import re
    import time

    from fastapi.testclient import TestClient

    from texsense.station.server import create_ward_app

    st = ward(3)
    assert st.mats["m000"].feed(Frame(0, np.zeros(1024), np.full(1024, 0.5), "N/cm2"), time.time())
    unit = "</script><script>alert(1)</script>"  # told back in the mat's error
    nasty = json.dumps({"seq": 0, "t": 0.0, "values": [0.5] * 1024, "unit": unit}).encode()
    assert not st.mats["m001"].handle(nasty, time.time())
    with TestClient(create_ward_app(st), base_url="http://127.0.0.1:8766") as client:
        html = client.get("/").text
    block = re.search(r'<script type="application/json" id="first-ward">(.*?)</script>', html)
    assert block is not None and "<" not in block.group(1)
    assert html.count("<script") == 3  # the block and the page's two scripts, nothing else
    first = json.loads(block.group(1))
    assert first["type"] == "ward" and first["reset"]
    tiles = {m["id"]: m for m in first["mats"]}
    assert set(tiles) == {"m000", "m001", "m002"}
    assert tiles["m000"]["state"] == "live" and tiles["m000"]["map"]["rows"] == 16
    assert unit in tiles["m001"]["last_error"]  # the text is all there, as text


def test_a_tile_does_not_make_the_snapshot_maps():
    """A tile (made for every changed mat of a group member every second) and the status read
    the snapshot's statistics and bed without making its maps' lists (~0.3 ms a mat); the maps
    are made when somebody asks for them, and the tile says the same either way."""
    st = ward(2)
    e = st.mats["m000"]
    e.feed(Frame(1, np.full(1024, 1.0), np.linspace(0, 2, 1024), "N/cm2"), 1.0)
    tile = json.loads(e.tile())
    assert e.monitor._maps is not None  # still waiting to be made
    assert tile["peak_mmhg"] is not None and tile["map"] is not None
    pressure = e.monitor.latest["pressure"]  # made now, once
    assert e.monitor._maps is None and len(pressure) == 1024
    e.version += 1  # a new revision: the tile is made again, from the same snapshot
    assert json.loads(e.tile()) == tile
