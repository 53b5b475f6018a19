"""A Mosquitto broker of the station's own on loopback (Debian's ``mosquitto``).

``texsense station`` starts one unless ``--broker URL`` names a running broker; the tests use
it to stop and restart a real broker under a running station. ``scripts/test.sh`` and
``scripts/run.sh`` install the package with apt-get when it is missing.

Examples
--------
>>> parse_broker_url("mqtt://ward:secret@10.0.0.2:1884").port
1884
>>> parse_broker_url("mqtts://broker.example").tls
True
"""

from __future__ import annotations

import contextlib
import ctypes
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlsplit

from texsense.exceptions import ParameterError

__all__ = ["Broker", "BrokerURL", "mqtt_client", "parse_broker_url"]


@dataclass(frozen=True)
class BrokerURL:
    """Where a broker is and how to log in (passed through to paho)."""

    host: str
    port: int
    username: str | None = None
    password: str | None = None
    tls: bool = False

    def __str__(self) -> str:
        scheme = "mqtts" if self.tls else "mqtt"
        user = f"{self.username}@" if self.username else ""
        return f"{scheme}://{user}{self.host}:{self.port}"


def parse_broker_url(url: str) -> BrokerURL:
    """``mqtt://[user[:password]@]host[:port]`` (``mqtts://`` for TLS, default port 8883)."""
    parts = urlsplit(url)
    if parts.scheme not in ("mqtt", "mqtts") or not parts.hostname:
        raise ParameterError(f"broker URL {url!r}: expected mqtt://host[:port] or mqtts://...")
    tls = parts.scheme == "mqtts"
    try:
        port = parts.port or (8883 if tls else 1883)
    except ValueError:
        raise ParameterError(f"broker URL {url!r}: the port is not a number") from None
    return BrokerURL(
        parts.hostname,
        port,
        unquote(parts.username) if parts.username else None,
        unquote(parts.password) if parts.password else None,
        tls,
    )


def mqtt_client(broker: BrokerURL, name: str) -> Any:
    """A paho client for ``broker`` (credentials and TLS set, reconnecting every 1-2 s),
    connecting in its own network thread; the caller sets its callbacks first if it needs
    them, then calls ``loop_start()``."""
    import paho.mqtt.client as mqtt

    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=name)
    if broker.username:
        client.username_pw_set(broker.username, broker.password)
    if broker.tls:
        client.tls_set()
    client.reconnect_delay_set(min_delay=1, max_delay=2)
    client.connect_async(broker.host, broker.port, keepalive=10)
    return client


def _die_with_parent() -> None:
    """In the child before exec (Linux): end with the parent, even one that is killed. (As
    root, Mosquitto drops to its own user at start, which clears this: a station killed with
    SIGKILL then leaves its broker running; Ctrl-C and SIGTERM stop it either way.)"""
    with contextlib.suppress(OSError):  # not Linux: the parent's stop() is the only way
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Broker:
    """A Mosquitto process listening on 127.0.0.1 only (anonymous clients, no persistence).

    Parameters
    ----------
    port : int, optional
        Default: a free port.
    """

    def __init__(self, port: int | None = None) -> None:
        exe = shutil.which("mosquitto") or next(
            (p for p in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto") if Path(p).exists()),
            None,
        )
        if exe is None:
            raise ParameterError(
                "Mosquitto is not installed: 'apt-get install mosquitto' (scripts/run.sh does "
                "it when run as root), or give a running broker with --broker mqtt://host:port"
            )
        self.exe = exe
        self.port = port or _free_port()
        self._dir = Path(tempfile.mkdtemp(prefix="texsense-broker-"))
        self.config = self._dir / "mosquitto.conf"
        self.config.write_text(
            f"listener {self.port} 127.0.0.1\nallow_anonymous true\npersistence false\n"
            f"log_dest file {self._dir / 'mosquitto.log'}\n",
            encoding="utf-8",
        )
        self._proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> BrokerURL:
        """Where clients connect."""
        return BrokerURL("127.0.0.1", self.port)

    def start(self, timeout_s: float = 10.0) -> Broker:
        """Start the process and wait until it accepts connections."""
        if self.running:
            return self
        errors = self._dir / "mosquitto.err"
        with errors.open("wb") as err:
            self._proc = subprocess.Popen(
                [self.exe, "-c", str(self.config)],
                stdout=subprocess.DEVNULL,
                stderr=err,
                preexec_fn=_die_with_parent,
            )
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self._proc.poll() is not None:
                text = errors.read_text(errors="replace").strip()[:300]
                raise ParameterError(f"mosquitto exited at start: {text}")
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.2):
                    return self
            except OSError:
                time.sleep(0.05)
        self.stop()
        raise ParameterError(f"mosquitto did not accept connections on port {self.port}")

    @property
    def running(self) -> bool:
        """True while the process runs."""
        return self._proc is not None and self._proc.poll() is None

    def stop(self) -> None:
        """Stop the process (clients see the connection drop)."""
        if self._proc is not None and self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        self._proc = None

    def __enter__(self) -> Broker:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
