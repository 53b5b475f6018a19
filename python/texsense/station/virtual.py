"""Virtual mats for the station: simulated people on virtual seats who publish their frames
through the broker, so that a ward can be seen and load-tested without hardware.

``texsense station --virtual-mats N`` runs them in a process of their own
(:meth:`VirtualMats.run_apart`), as real mats are devices of their own: simulating 20 mats
in the station's event loop held it for seconds at a time, and the ward page waited behind
them (issue 33: 40 s before its first tile under 20 mats at 10x on a shared 2-core machine).
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import json
import logging
import math
import multiprocessing
import signal
from typing import TYPE_CHECKING, Any

from texsense.data.protocol import Frame
from texsense.exceptions import ParameterError
from texsense.monitor.sources import Source
from texsense.monitor.virtual import VirtualBedSource, VirtualSeatSource
from texsense.station.broker import BrokerURL, mqtt_client
from texsense.station.config import MatConfig

if TYPE_CHECKING:
    from texsense.apps.posture.model import PostureModel
    from texsense.compensation.stages import StageChain

__all__ = ["VirtualMats", "frame_payload"]

log = logging.getLogger("texsense.station")


def frame_payload(frame: Frame) -> bytes:
    """The MQTT payload of a frame (docs/monitor.md): JSON with ``null`` for failed readings."""
    values = [None if not math.isfinite(v) else round(float(v), 5) for v in frame.values]
    return json.dumps(
        {
            "seq": frame.seq,
            "t": round(frame.t, 6),
            "dt": round(float(frame.element_times[1] - frame.element_times[0]), 9)
            if frame.element_times.size > 1
            else 0.0,
            "values": values,
            "unit": frame.unit,
        },
        separators=(",", ":"),
    ).encode()


class VirtualMats:
    """``n`` simulated people publishing to ``<prefix>/vmat-NN/frames``: the odd-numbered
    ones sit on a virtual 96-element textile seat (postures, standing up, failing elements:
    :class:`~texsense.monitor.virtual.VirtualSeatSource`), the even-numbered ones lie on a
    virtual 64 x 32 bed mat (every side and its variants, turning, sitting up, out of bed:
    :class:`~texsense.monitor.virtual.VirtualBedSource`); with ``beds``, only the first
    ``beds`` even-numbered ones (the others sit).

    Parameters
    ----------
    speed : float
        Simulated time per wall second (the seat scans a frame every 1.6 s simulated).

    Attributes
    ----------
    logins : dict of mat id -> BrokerURL, optional
        Each mat's own credentials (the station's own broker): each mat then connects as
        itself, as real mats do; without them the mats share one connection of ``broker``.
    """

    def __init__(
        self,
        n: int,
        broker: BrokerURL | None,
        *,
        prefix: str = "texsense",
        speed: float = 1.0,
        seed: int = 0,
        hold_s: float = 90.0,
        beds: int | None = None,
    ) -> None:
        self.broker = broker
        self.n, self.speed, self.seed, self.hold_s = n, speed, seed, hold_s
        self.prefix = prefix.strip("/")
        self.ids = [f"vmat-{k + 1:02d}" for k in range(n)]
        beds = n // 2 if beds is None else beds
        if not 0 <= beds <= n // 2:
            raise ParameterError(f"{n} virtual mats have 0-{n // 2} beds (every second one)")
        self.sources: list[Source] = [
            VirtualBedSource(speed=speed, seed=seed + k, hold_s=4 * hold_s)
            if k % 2 == 1 and k // 2 < beds
            else VirtualSeatSource(speed=speed, seed=seed + k, hold_s=hold_s)
            for k in range(n)
        ]
        self.published = 0
        self.logins: dict[str, BrokerURL] | None = None

    @property
    def beds(self) -> int:
        """How many of them are beds."""
        return sum(isinstance(s, VirtualBedSource) for s in self.sources)

    def topics(self) -> dict[str, str]:
        """Each mat's topic."""
        return {i: f"{self.prefix}/{i}/frames" for i in self.ids}

    def configs(
        self,
        seat_calibration: StageChain,
        bed_calibration: StageChain | None,
        reposition_min: float = 20.0,
        bed_model: PostureModel | None = None,
        turn_every_min: float = 120.0,
    ) -> list[MatConfig]:
        """The station's view of these mats (the seats share the seat's calibration, the beds
        the bed's; with ``bed_model``, a side model, the beds run the turning schedule)."""
        out = []
        for i, src in zip(self.ids, self.sources, strict=True):
            bed = isinstance(src, VirtualBedSource)
            out.append(
                MatConfig(
                    i, src.layout, bed_calibration if bed else seat_calibration,
                    source=f"mqtt ({src.name})", reposition_min=reposition_min,
                    bed=bed and bed_model is not None, posture_model=bed_model if bed else None,
                    turn_every_min=turn_every_min, rate=self.speed,
                )
            )  # fmt: skip
        return out

    async def _one(self, mat_id: str, source: Source, client: Any) -> None:
        topic = f"{self.prefix}/{mat_id}/frames"
        async for frame in source.frames():
            client.publish(topic, frame_payload(frame), qos=0)
            self.published += 1

    async def run(self) -> None:
        """Publish until cancelled (paho reconnects by itself if the broker restarts)."""

        if self.logins is None:
            if self.broker is None:
                raise ParameterError("the virtual mats need a broker to publish to")
            shared = mqtt_client(self.broker, f"texsense-vmats-{id(self)}")
            clients = dict.fromkeys(self.ids, shared)
        else:
            clients = {i: mqtt_client(self.logins[i], f"texsense-{i}-{id(self)}") for i in self.ids}
        for c in set(clients.values()):
            c.loop_start()
        try:
            await asyncio.gather(
                *(self._one(i, s, clients[i]) for i, s in zip(self.ids, self.sources, strict=True))
            )
        finally:
            for c in set(clients.values()):
                c.disconnect()
                c.loop_stop()

    async def run_apart(self) -> None:
        """:meth:`run` in a process of its own (see the module), until cancelled; it ends
        with the station (also one killed: the child asks the kernel for that)."""
        ctx = multiprocessing.get_context("spawn")  # a fresh interpreter: no loop, no threads
        args = (self.n, self.broker, self.logins, self.prefix, self.speed, self.seed, self.hold_s,
                self.beds)  # fmt: skip
        proc = ctx.Process(target=_publish_apart, args=args, daemon=True,
                           name="texsense-virtual-mats")  # fmt: skip
        # the child starts with Ctrl-C ignored (Python keeps an ignored SIGINT ignored): a
        # Ctrl-C on the terminal is the station's, which then stops the child itself; one
        # arriving while the child still imports would print a traceback
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            proc.start()
        finally:
            signal.signal(signal.SIGINT, previous)
        try:
            while proc.is_alive():
                await asyncio.sleep(0.5)
            log.warning("the virtual mats stopped (exit code %s)", proc.exitcode)
        finally:
            if proc.is_alive():
                proc.terminate()
                await asyncio.to_thread(proc.join, 5.0)


def _publish_apart(
    n: int,
    broker: BrokerURL | None,
    logins: dict[str, BrokerURL] | None,
    prefix: str,
    speed: float,
    seed: int,
    hold_s: float,
    beds: int,
) -> None:
    """The virtual mats' process: publish until the station ends it (Ctrl-C is the
    station's: it stops this process itself)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with contextlib.suppress(OSError, AttributeError):  # Linux: end with the station
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    vm = VirtualMats(n, broker, prefix=prefix, speed=speed, seed=seed, hold_s=hold_s, beds=beds)
    vm.logins = logins
    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(vm.run())
