"""The MicroPython reference sender (examples/microcontroller) under CPython against a
simulated AD7745 and multiplexers: its lines parse, in order, with the capacitances set."""

import asyncio
import importlib.util

import numpy as np
import pytest
import serial

from conftest import ROOT
from texsense import Layout
from texsense.monitor import SerialSource

SENDER = ROOT / "examples" / "microcontroller" / "texsense_sender.py"


def load_sender():
    spec = importlib.util.spec_from_file_location("texsense_sender", SENDER)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class Pin:
    def __init__(self) -> None:
        self.v = 1

    def value(self, v: int) -> None:
        self.v = v


class FakeAD7745:
    """Register-level AD7745: CIN1 sees the capacitance of the element the multiplexers
    route to it; a conversion is ready after two status polls; ``fail`` elements NAK."""

    def __init__(self, caps_pf, select, enable, fail=()) -> None:
        self.caps, self.select, self.enable, self.fail = caps_pf, select, enable, set(fail)
        self.regs = bytearray(20)
        self.regs[0] = 0x07
        self.polls = 0
        self.reset = False

    def element(self) -> int | None:
        on = [k for k, p in enumerate(self.enable) if p.v == 0]
        if len(on) != 1:
            return None  # nothing or two multiplexers on CIN1
        ch = sum(p.v << b for b, p in enumerate(self.select))
        return on[0] * 16 + ch

    def writeto(self, addr, data) -> None:
        assert addr == 0x48 and bytes(data) == b"\xbf"
        self.reset = True

    def writeto_mem(self, addr, reg, data) -> None:
        assert addr == 0x48 and self.reset
        self.regs[reg] = data[0]
        if reg == 0x0A and data[0] & 0x07 == 0x02:  # single conversion
            e = self.element()
            if e in self.fail:
                raise OSError(5, "EIO")
            dac = self.regs[0x0B]
            dac_pf = (dac & 0x7F) * 17.0 / 127 if dac & 0x80 else 0.0
            code = round((self.caps[e] - dac_pf) / (4.096 / 0x800000)) + 0x800000
            code = min(max(code, 0), 0xFFFFFF)
            self.regs[1:4] = code.to_bytes(3, "big")
            self.regs[0] = 0x01  # busy
            self.polls = 0

    def readfrom_mem(self, addr, reg, n) -> bytes:
        if reg == 0:
            self.polls += 1
            if self.polls >= 2:
                self.regs[0] = 0x00
        return bytes(self.regs[reg : reg + n])


class FakeTicks:
    """ticks_us that wraps at 2**30 like MicroPython's, advanced by sleep_us."""

    def __init__(self, start: int) -> None:
        self.t = start

    def ticks_us(self) -> int:
        return self.t % 2**30

    def ticks_diff(self, a: int, b: int) -> int:
        return ((a - b + 2**29) % 2**30) - 2**29

    def sleep_us(self, us: int) -> None:
        self.t += us + 150  # + the I2C transfer


def test_sender_lines_parse_to_the_capacitances_it_read():
    s = load_sender()
    n = 40
    rng = np.random.default_rng(3)
    caps = rng.uniform(2.0, 9.0, n)
    caps[3] = 12.0  # beyond CAPDAC + 4.096 pF: the converter saturates
    select, enable = [Pin() for _ in range(4)], [Pin() for _ in range(3)]
    chip = FakeAD7745(caps, select, enable, fail={7})
    ticks = FakeTicks(2**30 - 50_000)  # the tick counter wraps during the first frame
    sender = s.Sender(
        chip, select, enable, s.Clock(ticks.ticks_us, ticks.ticks_diff), n, ticks.sleep_us
    )
    sender.setup()
    port = serial.serial_for_url("loop://", timeout=0.2)  # the USB serial line
    port.write(b"# texsense sender: AD7745, 40 elements\n")
    for _ in range(3):
        port.write(sender.frame().encode("ascii"))
    source = SerialSource("loop://", Layout.grid(5, 8), opener=lambda *a, **k: port)

    async def read(k: int) -> list:
        it = source.frames()
        return [await asyncio.wait_for(anext(it), 5) for _ in range(k)]

    frames = asyncio.run(read(3))
    assert source.errors == 0
    assert [f.seq for f in frames] == [0, 1, 2]
    for f in frames:
        assert np.isnan(f.values[7])
        ok = np.arange(n) != 7
        top = s.CAPDAC_CODE * s.CAPDAC_FULL_PF / 127 + 4.096
        np.testing.assert_allclose(f.values[ok], np.minimum(caps, top)[ok], atol=1e-4)
        assert np.all(np.diff(f.element_times) > 0)
    # time runs on across the tick wrap; the element period is what was slept
    assert frames[1].t > frames[0].t and frames[2].t > frames[1].t
    assert frames[0].element_times[1] - frames[0].element_times[0] == pytest.approx(
        (s.SETTLE_US + 1000 + 2 * 150) * 1e-6, rel=0.05
    )


def test_sender_refuses_more_elements_than_multiplexer_channels():
    s = load_sender()
    with pytest.raises(ValueError, match="multiplexer"):
        s.Sender(None, [Pin()] * 4, [Pin()] * 2, None, 33)
