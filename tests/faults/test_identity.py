"""Family "a mat that claims another identity" and "the station's own broker dies" (issue 32,
item 3), against a running ``texsense station`` with its own Mosquitto and three mats: every
mat tries every other mat's client id, topic and every subscription a spy would make; the
station's user is tried with a mat's password. Then the broker is killed: the station starts
it again on the same port, the mats reconnect, and once the station stops no broker and no
temporary folder is left.
"""

from __future__ import annotations

import itertools
import json
import os
import signal
import time
import tomllib

import pytest

from faults.test_stop import broker_processes
from faults.test_ward import WardStation, enterable_folder

MATS = {"a": "4x4", "b": "4x4", "c": "4x4"}
#: what a spy subscribes to
SPY_FILTERS = ["#", "texsense/+/frames", "texsense/{other}/frames", "$SYS/#"]


def _client(st: WardStation, user: str, client_id: str):
    """A paho client logged in as the mat ``user`` under ``client_id``; (client, events)."""
    import paho.mqtt.client as mqtt

    password = tomllib.loads((st.folder / "mat-credentials.toml").read_text())["mats"][user]
    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id)
    c.username_pw_set(user, password)
    events: list = []
    c.on_connect = lambda _c, _u, _f, rc, _p=None: events.append(("connect", str(rc)))
    c.on_disconnect = lambda *_a: events.append(("disconnect",))
    c.on_message = lambda _c, _u, msg: events.append(("message", msg.topic))
    c.reconnect_delay_set(5, 5)
    c.connect("127.0.0.1", st.broker_port)
    c.loop_start()
    deadline = time.monotonic() + 5
    while not events and time.monotonic() < deadline:
        time.sleep(0.02)
    return c, events


def _frame(seq: int) -> bytes:
    return json.dumps({"seq": seq, "t": seq * 1.0, "values": [0.5] * 16, "unit": "N/cm2"}).encode()


@pytest.fixture(scope="module")
def ward():
    with enterable_folder() as folder, WardStation(folder, MATS) as st:
        yield st


def test_no_mat_can_take_another_mats_place(ward, fault_row):
    st = ward
    seq = dict.fromkeys(MATS, 0)
    tried = 0
    for intruder, victim in itertools.permutations(MATS, 2):
        owner, owner_events = _client(st, victim, victim)  # the victim, connected as itself
        # the victim's client id, the intruder's own user and password
        spy, events = _client(st, intruder, victim)
        for pattern in SPY_FILTERS:
            spy.subscribe(pattern.format(other=victim))
        before = st.mat(victim)["frames"]
        spy.publish(f"texsense/{victim}/frames", _frame(10_000 + tried)).wait_for_publish(5)
        owner.publish(f"texsense/{victim}/frames", _frame(seq[victim])).wait_for_publish(5)
        seq[victim] += 1
        st.until(lambda v=victim: st.mat(v)["frames"], lambda n, b=before: n == b + 1)
        time.sleep(0.2)
        assert ("disconnect",) not in owner_events, (intruder, victim, owner_events)
        assert not [e for e in events if e[0] == "message"], (intruder, victim, events)
        assert st.mat(victim)["frames"] == before + 1  # the owner's frame only
        for c in (spy, owner):
            c.disconnect()
            c.loop_stop()
        tried += 1
    fault_row(
        "identity",
        f"{tried} mats x another mat's client id, topic and {len(SPY_FILTERS)} subscriptions",
        "refused",
        "the other mat stays connected, gets no foreign frame; the spy reads nothing",
        cases=tried * (2 + len(SPY_FILTERS)),
    )


def test_the_stations_user_cannot_be_borrowed(ward, fault_row):
    st = ward
    password = tomllib.loads((st.folder / "mat-credentials.toml").read_text())["mats"]["a"]
    c, answers = st.client("texsense-station", password)
    try:
        assert answers and answers[0].is_failure, answers
    finally:
        c.disconnect()
        c.loop_stop()
    fault_row("identity", "the station's user with a mat's password", "refused")


def test_the_stations_broker_is_restarted_and_removed(fault_row):
    with enterable_folder() as folder:
        st = WardStation(folder, {"a": "4x4"})
        try:
            own = folder / "texsense-broker-"
            port = st.broker_port
            st.frame("a")
            st.until(lambda: st.mat("a")["frames"], lambda n: n == 1)
            pids = broker_processes(own)
            assert len(pids) == 1, pids
            os.kill(pids[0], signal.SIGKILL)
            st.until(lambda: st.log(), lambda log: "runs again on port" in log, 30)
            assert st.broker_port == port and broker_processes(own) != pids
            st.until(lambda: st.get("api/ward")["connected"], bool, 30)
            st.clients.clear()  # the mat connects anew, as a real mat's reconnect would
            st.frame("a")
            st.until(lambda: st.mat("a")["frames"], lambda n: n == 2, 30)
            fault_row("identity", "the station's broker killed", "restarted",
                      "the same port and users; the mat's next frame arrives")  # fmt: skip
        finally:
            st.stop()
        assert broker_processes(own) == []
        assert not list(folder.glob("texsense-broker-*")), list(folder.iterdir())
        assert "Traceback" not in st.log()
        fault_row("identity", "the station stopped after its broker was restarted", "stopped",
                  "no broker and no temporary folder left")  # fmt: skip
