"""Fault battery, a group of stations (docs/station.md, "A group of stations"): three members
and 60 virtual mats (issue 38's scale), with a real PostgreSQL, a real Mosquitto and the
virtual seats' frames published as processes (one cluster for the module, the cases in
order): made once and replayed (tests/replay_mats.py), or with
TEXSENSE_GROUP_PUBLISHER=simulate by `texsense simulate mats` for every frame. A
fourth station, alone in a group of its own (its own database), reads the same frames and is
never harmed: the reference run without the fault, which the group's exposure timers and
alerts are compared with."""

from __future__ import annotations

import os
import re
import shutil
import sys
import tempfile
import time
import urllib.error
import urllib.request
from collections import Counter
from pathlib import Path

import numpy as np
import psycopg
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from group_cluster import Cluster
from texsense.station.lease import preferred

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "monitor"))
from test_browser import open_page

MEMBERS = ["a", "b", "c"]
#: 60 mats at 4x, each publishing every 4th frame of its seat (a frame every 6.4 simulated s,
#: every 1.6 s of wall time): 37.5 frames a second to publish and for the reference to read
#: (every frame at 8x: 300 a second, 8 times the CPU), an alert after 75 s of sitting
#: (--reposition-min is 5 at the least: the reference's first alert sets the module's length
#: unless the faults take longer). A takeover's gap (the frames published while nobody held
#: the mat, ~1-3 s of wall time) is 4 times as long in simulated time: the alerts and timers
#: are judged in simulated s. Smaller runs: TEXSENSE_GROUP_MATS=6 TEXSENSE_GROUP_EVERY=1.
MATS = int(os.environ.get("TEXSENSE_GROUP_MATS", "60"))
SPEED = float(os.environ.get("TEXSENSE_GROUP_SPEED", "4"))
EVERY = int(os.environ.get("TEXSENSE_GROUP_EVERY", "4"))
#: how often the test reads the members' pages (each read of 60 mats costs the member and
#: the test a few ms of a core), s
POLL_S = 0.5
REPOSITION_MIN = 5.0
REPLAY = os.environ.get("TEXSENSE_GROUP_PUBLISHER", "replay") != "simulate"
#: a killed member's mats are back within this (issue 38), s
TAKEOVER_S = 10.0
#: the group raises each of the reference's alerts within this of the reference's time
#: (simulated s), and within the time in which their exposures may differ (frames_apart: a
#: run of frames one never saw and the other did not miss alike, such as a takeover's gap,
#: from the frame read before it to the one after; frames peeked at while far behind): that
#: time counts as loaded where a frame read on either side of it is (ExposureTracker.step),
#: so an alert comes at most that much later, and earlier by a relief that fell inside it
#: (tests/monitor/test_alerts.py, docs/station.md "What is lost at worst")
ALERT_TOL_S = 10.0
#: a mat's frame period in simulated s (the seat's 1.6 s, every EVERY-th published)
FRAME_S = 1.6 * EVERY

#: the members' READY_S (texsense's: 10 s), s
READY_S = 3.0

#: One worker runs the whole module (pytest-xdist's --dist loadgroup): the cases share one
#: cluster and run in order (a member is killed, then comes back).
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("group_cluster")]


@pytest.fixture(scope="module")
def cluster():
    folder = Path(tempfile.mkdtemp(prefix="texsense-group-", dir="/tmp"))
    folder.chmod(0o755)  # Mosquitto and PostgreSQL run as their own users under root
    # READY_S 3 s (tests/group_ready): the setup waited 10 s of beats before the first member
    # gave the others their mats, before the mats publish (the cases after it wait on the
    # simulated time of the alerts, which runs from the publishing)
    c = Cluster(folder, MEMBERS, MATS, speed=SPEED, reposition_min=REPOSITION_MIN,
                publish=False, ready_s=READY_S)  # fmt: skip
    try:
        c.reference_db = c.database("reference")  # type: ignore[attr-defined]
        c.start("ref", group="ref", db=c.reference_db)  # type: ignore[attr-defined]
        # the mats publish once every station is up and the group has settled (rendezvous
        # hashing's answer): the reference and the group read them from the same first frame
        settled = {f"vmat-{k + 1:02d}": preferred(f"vmat-{k + 1:02d}", MEMBERS)
                   for k in range(MATS)}  # fmt: skip
        for who, holders in (("a", settled), ("ref", dict.fromkeys(settled, "ref"))):
            c.until(lambda who=who: (c.get(who, "api/ward"), c.mats_of(who)),
                    lambda hm, holders=holders: hm[0]["connected"] and
                    {k: m["holder"] for k, m in hm[1].items()} == holders, 240,
                    step=POLL_S)  # fmt: skip
        for who in ("b", "c"):
            c.until(
                lambda who=who: c.get(who, "api/ward"), lambda h: h["connected"], 60, step=POLL_S
            )
        c.publish(replay=REPLAY, every=EVERY)
        yield c
    finally:
        c.close()
    if not os.environ.get("TEXSENSE_GROUP_KEEP"):  # the members' logs, to read after a run
        shutil.rmtree(folder, ignore_errors=True)


def live(mats: dict, since: dict | None = None) -> bool:
    """Every mat live (or alerting) with frames after ``since``."""
    return all(m["state"] in ("live", "alert", "acknowledged") and
               (since is None or m["frames"] > since[k]["frames"])
               for k, m in mats.items())  # fmt: skip


def test_the_members_share_the_mats(cluster, fault_row):
    cluster.all_held("a", timeout=180)  # the members start, on 2 shared cores
    cluster.all_held("ref", timeout=60)
    # the first member up takes every mat; the others get theirs (rendezvous hashing) once
    # they have been beating for READY_S without a break
    settled = {k: preferred(k, MEMBERS) for k in cluster.mats_of("a")}
    mats = cluster.until(lambda: cluster.mats_of("a"), lambda s: live(s) and
                         {k: m["holder"] for k, m in s.items()} == settled, 60)  # fmt: skip
    held = Counter(m["holder"] for m in mats.values())
    assert set(held) == set(MEMBERS), held
    for member in ("b", "c"):  # every member's page shows every mat, with the same holder
        seen = cluster.until(lambda member=member: cluster.mats_of(member),
                             lambda s: {k: m["holder"] for k, m in s.items()} ==
                             {k: m["holder"] for k, m in mats.items()}, 10)  # fmt: skip
        assert len(seen) == MATS
    header = cluster.get("a", "api/ward")
    assert header["group"] == "ward" and header["member"] == "a" and header["unwatched"] == 0
    assert sorted(m for m, v in header["members"].items() if v["alive"]) == MEMBERS
    fault_row("group", f"three members share {MATS} mats", "said", f"held {dict(held)}")


def test_a_mat_held_elsewhere_is_its_holders(cluster):
    mats = cluster.mats_of("a")
    mat = next(k for k, m in mats.items() if m["holder"] == "c")
    req = urllib.request.Request(cluster.url("a") + f"mats/{mat}/")

    class NoRedirect(urllib.request.HTTPRedirectHandler):
        def redirect_request(self, *args, **kwargs):
            return None

    with pytest.raises(urllib.error.HTTPError) as e:
        urllib.request.build_opener(NoRedirect).open(req, timeout=5)
    e.value.close()
    assert e.value.code == 307
    assert e.value.headers["location"] == cluster.url("c") + f"mats/{mat}/"


def timers(cluster, member: str) -> dict[str, float]:
    """Each mat's exposure timer (the longest exposure of an element), s."""
    return {k: m["exposure_s"] for k, m in cluster.mats_of(member).items()}


def off_reference(cluster, member: str, mats: set[str], timeout: float = 30.0) -> dict:
    """How far each of ``mats``' timer on ``member`` is from the reference's at the same frame
    time (simulated s, + ahead): both are read until each of our readings of every mat lies
    between two of the reference's (a timer runs linearly between them; the two stations read
    the frames a moment apart, a loaded member seconds later), and the reference's timer
    interpolated at our readings' frame times."""
    seen: dict[str, dict[str, dict[float, float]]] = {member: {}, "ref": {}}

    def between() -> dict[str, list[float]]:
        out = {}
        for k in mats:
            rt = sorted(seen["ref"].get(k, {}))
            out[k] = [t for t in seen[member].get(k, {}) if rt and rt[0] <= t <= rt[-1]]
        return out

    deadline = time.monotonic() + timeout
    while not all(len(v) >= 2 for v in between().values()):
        assert time.monotonic() < deadline, {
            k: (sorted(seen[member].get(k, {}))[-3:], sorted(seen["ref"].get(k, {}))[-3:])
            for k, v in between().items()
            if len(v) < 2
        }
        for who in seen:
            for k, m in cluster.mats_of(who).items():
                if k in mats and m["frame_t"] is not None:
                    seen[who].setdefault(k, {})[m["frame_t"]] = m["exposure_s"]
        time.sleep(POLL_S)
    off = {}
    for k, both in between().items():
        ref = seen["ref"][k]
        rt = sorted(ref)
        off[k] = float(np.median([seen[member][k][t] - np.interp(t, rt, [ref[r] for r in rt])
                                  for t in both]))  # fmt: skip
    return off


def test_a_killed_member_s_mats_are_taken_over(cluster, fault_row):
    before = cluster.mats_of("a")
    victims = {k for k, m in before.items() if m["holder"] == "b"}
    # the group's timers against the reference's before the fault (the reference started
    # a moment after the group: each counts from the first frame it read)
    start = off_reference(cluster, "a", victims)
    t0, killed = time.monotonic(), time.time()
    cluster.kill("b")

    def back(s: dict) -> bool:  # held by a survivor, live, a frame read there after the kill
        return all(s[k]["holder"] in ("a", "c") and s[k]["state"] in ("live", "alert",
                   "acknowledged") and (s[k]["last_frame_wall"] or 0.0) > killed
                   for k in victims)  # fmt: skip

    cluster.until(lambda: cluster.mats_of("a"), back, 30, step=0.1)
    took = time.monotonic() - t0
    assert took < TAKEOVER_S, f"{len(victims)} mats back after {took:.1f} s"
    # the exposure timers go on: within 10 s (simulated) of the run without the fault
    after = off_reference(cluster, "a", victims)
    off = {k: round(abs(after[k] - start[k]), 1) for k in victims}
    assert max(off.values()) <= 10.0, (off, start, after)
    assert any(v > 0 for k, v in timers(cluster, "ref").items() if k in victims)  # someone sat
    # what a nurse sees on a survivor's ward page: every mat watched, none by the dead member
    from playwright.sync_api import expect

    with open_page(cluster.url("a"), 1240, 900) as (page, errors):
        expect(page.locator(".tile")).to_have_count(len(before), timeout=20_000)
        held = page.locator(".tile .holder", has_text=re.compile(r"^watched by (a \(here\)|c)$"))
        expect(held).to_have_count(len(before), timeout=10_000)
        expect(page.locator(".tile.is-unwatched, .tile.is-stale")).to_have_count(0)
        assert not errors, errors
    fault_row(
        "group",
        "SIGKILL of a member",
        "mat live",
        f"{len(victims)} mats back in {took:.1f} s, timers within {max(off.values())} s",
    )


def test_a_member_that_comes_back_takes_a_share(cluster):
    cluster.start("b")
    settled = {k: preferred(k, MEMBERS) for k in cluster.mats_of("a")}
    # its start (a minute on the loaded machine), then READY_S of beats: b's mats go
    # back to it, every mat live
    cluster.until(lambda: cluster.mats_of("a"), lambda s: live(s) and
                  {k: m["holder"] for k, m in s.items()} == settled, 120)  # fmt: skip
    cluster.all_held("b")


def test_the_broker_restarts(cluster, fault_row):
    before = cluster.mats_of("a")
    cluster.broker.pause()
    cluster.until(lambda: cluster.get("a", "api/ward"), lambda h: not h["connected"], 10)
    cluster.broker.start()
    cluster.until(lambda: cluster.mats_of("a"), lambda s: live(s, before), 30)
    assert Counter(m["holder"] for m in cluster.mats_of("a").values()) == \
        Counter(m["holder"] for m in before.values())  # fmt: skip
    fault_row("group", "the broker restarts", "mat live", "every mat live again, same holders")


def test_postgresql_restarts(cluster, fault_row):
    before = cluster.mats_of("a")
    cluster.pg.stop()
    try:  # the members go on from memory: frames are read, timers run
        during = cluster.until(lambda: cluster.mats_of("a"), lambda s: live(s, before), 20)
        header = cluster.get("a", "api/ward")
        assert header["database"], header  # said on the page
    finally:
        cluster.pg.start()
    cluster.until(
        lambda: cluster.get("a", "api/ward"),
        lambda h: not h["database"] and h["unwatched"] == 0,
        30,
    )
    after = cluster.until(lambda: cluster.mats_of("a"), lambda s: live(s, during), 30)
    assert {k: m["holder"] for k, m in after.items()} == {k: m["holder"] for k, m in
                                                          before.items()}  # fmt: skip
    fault_row("group", "PostgreSQL restarts", "mat live", "the members go on from memory")


def reposition_alerts(url: str, group: str) -> dict[str, list[tuple[float, str]]]:
    """Every mat's alert events (t, kind) in a group's database."""
    out: dict[str, list[tuple[float, str]]] = {}
    with psycopg.connect(url) as c:
        for mat, t, kind in c.execute(
            "SELECT c.mat, e.t, e.kind FROM events e JOIN group_checkpoints c ON "
            "c.session = e.session AND c.grp = %s WHERE e.kind = 'reposition' ORDER BY e.t",
            (group,),
        ):
            out.setdefault(mat, []).append((round(float(t), 1), kind))
    return out


def checkpoint_times(url: str, group: str) -> dict[str, float]:
    """Each mat's latest checkpoint's frame time in a group's database: its events before it
    are all there (a member writes events and checkpoints in one ordered stream)."""
    with psycopg.connect(url) as c:
        rows = c.execute("SELECT mat, t FROM group_checkpoints WHERE grp = %s AND t IS NOT "
                         "NULL", (group,)).fetchall()  # fmt: skip
    return {str(m): float(t) for m, t in rows}


def frames_apart(ours: dict, theirs: dict) -> int:
    """The frame periods of a mat in which two stations' exposures may differ, from their
    ``GET /api/mats`` rows: each run of frames that one never saw (``missed_runs``) and the
    other did not miss alike spans its frames and one period more, from the frame read before
    it to the one after (that time counts as loaded where either of those is,
    ExposureTracker.step's ``skipped``: one frame lost at the start of a relief moves an
    alert two periods earlier); a run missed alike (the broker's frames while it was down,
    the same frames read on either side) is the same to both. Frames beyond the runs named
    (only the latest are) and frames peeked at, whose runs are not known, count twice."""
    runs = [{tuple(r) for r in s.get("missed_runs") or []} for s in (ours, theirs)]
    apart = sum(last - first + 2 for first, last in runs[0] ^ runs[1])
    for s, named in zip((ours, theirs), runs, strict=True):
        unnamed = (s.get("missed") or 0) - sum(last - first + 1 for first, last in named)
        apart += 2 * (max(unnamed, 0) + (s.get("peeked") or 0))
    return apart


def test_a_frame_lost_at_a_relief_is_within_the_tolerance():
    """One frame lost at a takeover just as a relief of two frames began, another by the
    reference at the broker's restart, while the person sat: the same count (1 and 1) is not
    the same frames, and the group's lost frame made the 12.8 s from the frame before it to
    the one after loaded (never relief: docs/station.md, "What is lost at worst"), two
    periods, more than the older tolerance (10 s + the difference of the counts) allowed.
    (Round 15's flake had the same numbers, with another cause: the sensor's state,
    tests/monitor/test_group_leases.py.) Judged as the fault test judges, on trackers."""
    from texsense import Layout
    from texsense.monitor import ExposureTracker

    loads = [1.0] * 4 + [0.0] * 2 + [1.0] * 60  # frames FRAME_S apart; relieved at 4 and 5
    lost = {"ours": 4, "ref": 31}
    raised = {}
    for who, frame in lost.items():
        tr = ExposureTracker(Layout.grid(1, 1), reposition_min=REPOSITION_MIN, offload_min=1)
        for k, p in enumerate(loads):
            if k == frame:
                continue
            events = tr.step(np.array([p]), k * FRAME_S, skipped=k == frame + 1)
            if any(e.kind == "reposition" for e in events):
                raised[who] = k * FRAME_S
                break
    rows = {who: {"missed": 1, "missed_runs": [[k, k]], "peeked": 0} for who, k in lost.items()}
    apart = raised["ref"] - raised["ours"]
    assert apart == pytest.approx(2 * FRAME_S)  # the group's alert two periods early
    assert apart <= ALERT_TOL_S + FRAME_S * frames_apart(rows["ours"], rows["ref"])
    # a run missed alike is the same to both
    assert frames_apart(rows["ours"], rows["ours"]) == 0


def test_the_alerts_of_the_reference_all_raised_none_twice(cluster, fault_row):
    def read() -> tuple[dict, dict, dict, dict]:
        seen = {who: cluster.mats_of(who) for who in ("a", "ref")}
        done = checkpoint_times(cluster.pg.url, "ward")
        ref_done = checkpoint_times(cluster.reference_db, "ref")
        horizon = {k: min(t, ref_done.get(k, 0.0)) for k, t in done.items()}
        return horizon, reposition_alerts(cluster.pg.url, "ward"), \
            reposition_alerts(cluster.reference_db, "ref"), seen  # fmt: skip

    def tolerance(mat: str, seen: dict) -> float:
        """ALERT_TOL_S and the time in which the group's and the reference's exposure of the
        mat may differ (:func:`frames_apart`), simulated s."""
        return ALERT_TOL_S + FRAME_S * frames_apart(seen["a"][mat], seen["ref"][mat])

    def said(mat: str, seen: dict) -> list:
        """What an assertion says of the mat: holder, behind, peeked, missed (its runs)."""
        return [[m.get(k) for k in ("holder", "behind", "peeked", "missed", "missed_runs")]
                for m in (seen["a"][mat], seen["ref"][mat])]  # fmt: skip

    def judged(r: tuple[dict, dict, dict, dict]) -> int:
        """The reference's alerts that both databases are the tolerance past: an alert is
        judged only that far before the horizon, where its twin in the other database is in
        too (a station that missed frames raises it up to their time later)."""
        horizon, _, reference, seen = r
        return sum(t < horizon.get(mat, 0.0) - tolerance(mat, seen)
                   for mat, v in reference.items() for t, _ in v)  # fmt: skip

    # until the reference has raised alerts enough that both databases are past (a person
    # sat for 5 simulated min: 75 s at 4x)
    enough = min(10, MATS)
    horizon, ours, reference, seen = cluster.until(read, lambda r: judged(r) >= enough,
                                                   200 * 4 / SPEED)  # fmt: skip
    n = 0
    worst = 0.0
    for mat in set(reference) | set(ours):
        tol = tolerance(mat, seen)
        until = horizon.get(mat, 0.0) - tol
        want = [t for t, _ in reference.get(mat, [])]
        got = [t for t, _ in ours.get(mat, [])]
        for w in (w for w in want if w < until):  # raised, once
            twins = [g for g in got if abs(g - w) <= tol]
            assert len(twins) == 1, (mat, got, want, tol, said(mat, seen))
            worst = max(worst, abs(twins[0] - w))
            n += 1
        for g in (g for g in got if g < until):  # none that the reference did not raise
            assert any(abs(g - w) <= tol for w in want), (mat, got, want, tol, said(mat, seen))
    assert n >= enough, n
    skims = {who: [sum(v.get(k) or 0 for v in seen[who].values())
                   for k in ("behind", "peeked", "missed")] for who in seen}  # fmt: skip
    fault_row(
        "group",
        "alerts across a takeover",
        "said",
        f"{n} alerts, none twice, "
        f"{worst:.1f} s apart at most; frames followed/peeked while behind, never seen: "
        f"group {skims['a'][0]}/{skims['a'][1]}, {skims['a'][2]}; reference "
        f"{skims['ref'][0]}/{skims['ref'][1]}, {skims['ref'][2]}",
    )
