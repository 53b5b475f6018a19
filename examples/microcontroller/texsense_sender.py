"""texsense reference sender (MicroPython): an AD7745 behind analog multiplexers -> the
texsense serial line protocol on the USB serial port.

Hardware (thesis §2.3.2 / §6.2.1): every sensor element is one electrode of a textile
capacitor whose other electrode is common (the excitation, EXCA of the AD7745). The element
electrodes go through 16:1 analog multiplexers (e.g. CD74HC4067; one per 16 elements, their
enable pins on ``ENABLE_PINS``) to CIN1+; ``SELECT_PINS`` drive the 4 address lines of all of
them. The AD7745 sits on I2C (address 0x48).

Per element: select it, let the electrode settle, start a single conversion, wait for it,
read the 24-bit result. One line per frame::

    F,<seq>,<t0_us>,<dt_us>,<C_1>,...,<C_N>*<XX>

(docs/monitor.md; ``t0_us`` is when element 1 was read, ``dt_us`` the mean time between two
elements, C in pF, an empty field where the I2C read failed, ``XX`` the XOR of all characters
before ``*``). Start the monitor with
``texsense monitor --source serial:/dev/ttyACM0 --grid 15x16 --calibration mat.json``.

Copy this file to the board as ``main.py`` and edit the pin numbers below. Runs on any
MicroPython port with ``machine.I2C`` (RP2040, ESP32, STM32); the tests run it under CPython
against a simulated AD7745 (tests/monitor/test_sender.py).
"""

import sys
import time

# --- configuration -----------------------------------------------------------------------
N_ELEMENTS = 96
I2C_BUS, SDA_PIN, SCL_PIN, I2C_HZ = 0, 4, 5, 400_000
SELECT_PINS = (10, 11, 12, 13)  # multiplexer address lines S0..S3
ENABLE_PINS = (14, 15, 16, 17, 18, 19)  # one active-low enable per multiplexer (16 elements)
SETTLE_US = 4700  # electrode settling after switching (thesis virtual mat: 4.7 ms)
CAPDAC_CODE = 40  # 0..127: subtracts a fixed capacitance so the readings stay in ±4.096 pF
CAPDAC_FULL_PF = 17.0  # nominal full range of the CAPDAC (parts vary: calibrate the mat)
CONVERSION = 1  # CAPF code: 0: 11.0 ms, 1: 11.9 ms (83.8 Hz), 2: 20 ms, ... 7: 109.6 ms

# --- AD7745 registers (datasheet, Rev. 0: register map) ----------------------------------
ADDRESS = 0x48
REG_STATUS, REG_CAP_DATA, REG_CAP_SETUP, REG_EXC_SETUP, REG_CONFIG, REG_CAPDAC_A = (
    0x00,
    0x01,
    0x07,
    0x09,
    0x0A,
    0x0B,
)
RESET = 0xBF
STATUS_RDYCAP = 0x01  # 0 when a capacitive conversion is ready
CAP_SETUP_CAPEN = 0x80  # capacitive channel on, CIN1, single-ended
EXC_SETUP = 0x08 | 0x03  # EXCA on, excitation ±VDD/2
MODE_SINGLE = 0x02
ZERO_CODE = 0x800000  # code of 0 pF; full scale ±4.096 pF
LSB_PF = 4.096 / ZERO_CODE


class Clock:
    """Microseconds since start that never wrap (MicroPython's ticks_us wraps)."""

    def __init__(self, ticks_us, ticks_diff):
        self.ticks_us, self.ticks_diff = ticks_us, ticks_diff
        self.last, self.total = ticks_us(), 0

    def now(self):
        t = self.ticks_us()
        self.total += self.ticks_diff(t, self.last)
        self.last = t
        return self.total


class Sender:
    """Reads the mat element by element; :meth:`frame` returns one protocol line."""

    def __init__(self, i2c, select_pins, enable_pins, clock, n_elements=N_ELEMENTS, sleep_us=None):
        self.i2c, self.select, self.enable = i2c, select_pins, enable_pins
        self.clock, self.n = clock, n_elements
        self.sleep_us = sleep_us or (lambda us: None)
        self.seq = 0
        if len(enable_pins) * 2 ** len(select_pins) < n_elements:
            raise ValueError("fewer multiplexer channels than elements")

    def setup(self):
        """Reset the converter, CIN1 single-ended, EXCA, CAPDAC A."""
        self.i2c.writeto(ADDRESS, bytes([RESET]))
        self.sleep_us(200)
        self.i2c.writeto_mem(ADDRESS, REG_CAP_SETUP, bytes([CAP_SETUP_CAPEN]))
        self.i2c.writeto_mem(ADDRESS, REG_EXC_SETUP, bytes([EXC_SETUP]))
        dac = 0x80 | (CAPDAC_CODE & 0x7F) if CAPDAC_CODE else 0
        self.i2c.writeto_mem(ADDRESS, REG_CAPDAC_A, bytes([dac]))

    def choose(self, element):
        """Route ``element`` to CIN1: address lines, then only its multiplexer enabled."""
        mux, channel = divmod(element, 2 ** len(self.select))
        for bit, pin in enumerate(self.select):
            pin.value((channel >> bit) & 1)
        for k, pin in enumerate(self.enable):
            pin.value(0 if k == mux else 1)

    def read_pf(self):
        """One single conversion, pF (None when the I2C transfer fails or times out)."""
        try:
            self.i2c.writeto_mem(ADDRESS, REG_CONFIG, bytes([(CONVERSION << 3) | MODE_SINGLE]))
            for _ in range(200):
                if not self.i2c.readfrom_mem(ADDRESS, REG_STATUS, 1)[0] & STATUS_RDYCAP:
                    break
                self.sleep_us(1000)
            else:
                return None
            b = self.i2c.readfrom_mem(ADDRESS, REG_CAP_DATA, 3)
        except OSError:
            return None
        code = (b[0] << 16) | (b[1] << 8) | b[2]
        return (code - ZERO_CODE) * LSB_PF + CAPDAC_CODE * CAPDAC_FULL_PF / 127

    def frame(self):
        """Read every element once; returns the protocol line (with newline)."""
        fields, times = [], []
        for i in range(self.n):
            self.choose(i)
            self.sleep_us(SETTLE_US)
            times.append(self.clock.now())
            c = self.read_pf()
            fields.append("" if c is None else f"{c:.6g}")
        dt = (times[-1] - times[0]) // (self.n - 1) if self.n > 1 else 0
        body = "F,{},{},{},{}".format(self.seq, times[0], dt, ",".join(fields))
        self.seq = (self.seq + 1) % 2**32
        x = 0
        for ch in body:
            x ^= ord(ch)
        return f"{body}*{x:02X}\n"


def main():  # pragma: no cover - runs on the board
    from machine import I2C, Pin

    i2c = I2C(I2C_BUS, sda=Pin(SDA_PIN), scl=Pin(SCL_PIN), freq=I2C_HZ)
    select = [Pin(p, Pin.OUT) for p in SELECT_PINS]
    enable = [Pin(p, Pin.OUT, value=1) for p in ENABLE_PINS]
    sender = Sender(
        i2c, select, enable, Clock(time.ticks_us, time.ticks_diff), N_ELEMENTS, time.sleep_us
    )
    sender.setup()
    sys.stdout.write(f"# texsense sender: AD7745, {N_ELEMENTS} elements\n")
    while True:
        sys.stdout.write(sender.frame())


if __name__ == "__main__":
    main()
