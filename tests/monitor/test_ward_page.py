"""The ward page's own behaviour under a nurse's pointer (docs/station.md, "The ward page"):
tiles are filled in place, so a click that lands while the ward updates is neither lost nor
taken by another mat, and the tiles do not move under a pointer that is aiming.

The page is the station's own ward.html and ward.js, opened from a folder with its WebSocket
and ``fetch`` replaced by recorders, and driven with messages made by a real station's
:class:`WardFeed`: what the page draws and what it posts is the page's doing alone."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from test_browser import open_page

from texsense import Layout
from texsense.data.protocol import Frame
from texsense.monitor.routes.static import STATIC as MONITOR_STATIC
from texsense.station.server import FIRST_MARK, STATIC
from texsense.station.tiles import WardFeed
from texsense.station.ward import MatConfig, Station

# the page's WebSocket never connects; what it posts is kept in window.posted
RECORDERS = """<script>
window.WebSocket = class { close() {} };
window.posted = [];
window.fetch = async (url, options) => {
  window.posted.push([url, options.method]);
  return { ok: true };
};
</script>"""


def ward_folder(tmp_path, first: str):
    """ward.html with ``first`` as its first message and the recorders, and its static files."""
    (tmp_path / "static").mkdir()
    for name in ("ward.js", "ward.css"):
        shutil.copyfile(STATIC / name, tmp_path / "static" / name)
    for name in ("colormaps.js", "style.css"):
        shutil.copyfile(MONITOR_STATIC / name, tmp_path / "static" / name)
    block = f'<script type="application/json" id="first-ward">{first}</script>'
    html = (STATIC / "ward.html").read_text(encoding="utf-8").replace(FIRST_MARK, block + RECORDERS)
    page = tmp_path / "ward.html"
    page.write_text(html, encoding="utf-8")
    return page.as_uri()


def sitting(st: Station, until_s: int, start_s: int = 0) -> None:
    """m001 sits hard from t = 0, m002 from t = 150, m000 and m003 lightly: 10 s frames."""
    for s in range(start_s, until_s + 1, 10):
        for k in range(len(st.mats)):
            hard = (k == 1) or (k == 2 and s >= 150)
            p = np.full(64, 1.5 if hard else 0.1)
            st.mats[f"m{k:03d}"].feed(Frame(s, np.full(64, float(s)), p, "N/cm2"), float(s))
        st.check_all(float(s))


def order(page) -> list[str]:
    return page.evaluate("() => [...document.querySelectorAll('.tile')].map((t) => t.dataset.id)")


@pytest.mark.slow
def test_a_click_during_an_update_acts_on_the_mat_under_the_pointer(tmp_path):
    from playwright.sync_api import expect

    grid = Layout.grid(8, 8)
    st = Station(
        None,
        [MatConfig(f"m{k:03d}", grid, quantity="pressure", reposition_min=5) for k in range(4)],
    )
    feed = WardFeed(st)
    sitting(st, 250)
    first = feed.message(now=250.0)
    with open_page(ward_folder(tmp_path, first), 1000, 700) as (page, errors):
        expect(page.locator(".tile")).to_have_count(4)
        assert order(page)[:2] == ["m001", "m002"]  # the longest above the threshold first
        held = page.locator('.tile[data-id="m001"]').element_handle()
        sitting(st, 400, 260)  # m001 has sat 5 min: its alert is open
        page.evaluate("(m) => render(JSON.parse(m))", feed.message(now=400.0))
        m001 = page.locator('.tile[data-id="m001"]')
        expect(m001).to_have_attribute("data-state", "alert")
        assert held.evaluate("(t) => t.isConnected")  # the same element, filled in place
        ack = m001.locator("button.ack")
        expect(ack).to_be_visible()
        alert_id = st.mats["m001"].status()["alert"]["id"]

        # m002 becomes the most urgent while the nurse's pointer is on m001's button
        tiles = {t["id"]: t for t in json.loads(WardFeed(st).message(now=400.0))["mats"]}
        urgent = json.loads(first) | {"reset": False, "mats": [tiles["m002"] | {"urgency": 9}]}
        box = ack.bounding_box()
        page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        page.mouse.down()
        page.evaluate("(m) => render(m)", urgent)  # between the button's down and up
        page.mouse.up()
        assert order(page)[0] == "m001"  # held still under the aiming pointer
        url = f"/api/mats/m001/alerts/{alert_id}/ack"
        assert page.evaluate("() => window.posted") == [[url, "POST"]]
        page.wait_for_timeout(2000)  # the pointer rests: the order catches up
        assert order(page)[0] == "m002"
        # a pointer parked on the page holds nothing: the next change moves at once
        urgent["mats"] = [tiles["m003"] | {"urgency": 10}]
        page.evaluate("(m) => render(m)", urgent)
        assert order(page)[0] == "m003"
        assert not errors, errors


@pytest.mark.slow
def test_a_group_s_tiles_say_who_watches_them_and_a_mat_nobody_watches_is_red(tmp_path):
    """In a group each tile names its holder; a mat that nobody holds is on top, red, and
    says so; a tile that changes holder loses the line it no longer needs."""
    from playwright.sync_api import expect

    st = Station(
        None, [MatConfig(f"m{k:03d}", Layout.grid(8, 8), quantity="pressure") for k in range(3)]
    )
    sitting(st, 100)
    msg = json.loads(WardFeed(st).message(now=100.0))
    members = {"a": {"alive": True}, "b": {"alive": True}}
    msg["header"] |= {"group": "ward", "member": "a", "members": members}
    holders = {"m000": "a", "m001": "b", "m002": None}
    for t in msg["mats"]:
        t["holder"] = holders[t["id"]]
        if t["holder"] is None:
            t |= {"state": "unwatched", "urgency": 5, "problem": "no station watches this mat"}
    with open_page(ward_folder(tmp_path, json.dumps(msg)), 1000, 700) as (page, errors):
        expect(page.locator(".tile")).to_have_count(3)
        assert order(page)[0] == "m002"
        tile = {k: page.locator(f'.tile[data-id="{k}"]') for k in holders}
        expect(tile["m000"].locator(".holder")).to_have_text("watched by a (here)")
        expect(tile["m001"].locator(".holder")).to_have_text("watched by b")
        expect(tile["m002"].locator(".holder")).to_have_text("no station watches it")
        expect(tile["m002"].locator(".state")).to_have_text("NOT WATCHED")
        expect(tile["m002"].locator(".problem")).to_have_text("no station watches this mat")
        red = tile["m002"].evaluate("(t) => getComputedStyle(t).backgroundColor")
        assert red == "rgb(254, 226, 226)", red
        # b takes m002 over; its problem line goes with the state it belonged to
        back = next(t for t in msg["mats"] if t["id"] == "m002")
        back = back | {"state": "live", "urgency": 1, "problem": None, "holder": "b"}
        page.evaluate("(m) => render(m)", msg | {"reset": False, "mats": [back]})
        expect(tile["m002"].locator(".holder")).to_have_text("watched by b")
        assert tile["m002"].locator(".problem").evaluate("(e) => e.hidden")
        assert tile["m002"].evaluate("(t) => t.title") == ""
        assert not errors, errors
