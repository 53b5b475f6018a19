"""A Mosquitto broker of the station's own on loopback (Debian's ``mosquitto``), and how the
station and its mats log in to any broker.

``texsense station`` starts one unless ``--broker URL`` names a running broker. Its own broker
lets nobody in without credentials: the station generates a password for itself (allowed to
read its topic filter only) and one per mat (allowed to publish to that mat's topic only: a
mat cannot pose as another), writes the password file and the ACL into the broker's
temporary folder and removes the folder when it stops. The MQTT mats' passwords are kept in a
file of the station's (``--mat-credentials``, mode 0600) so that real mats keep theirs from
one start to the next; the virtual mats get new ones at every start.

``scripts/test.sh`` and ``scripts/run.sh`` install the package with apt-get when it is missing.

Examples
--------
>>> parse_broker_url("mqtt://ward@10.0.0.2:1884").port
1884
>>> parse_broker_url("mqtts://broker.example").tls
True
>>> str(parse_broker_url("mqtt://ward:secret@10.0.0.2"))   # never shows the password
'mqtt://ward@10.0.0.2:1883'
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import ctypes
import hashlib
import json
import logging
import os
import pwd
import re
import secrets
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlsplit

from texsense.data.files import atomic_path, read_regular, toml_loads
from texsense.exceptions import FormatError, ParameterError, shown
from texsense.monitor.sources import blocking

__all__ = [
    "STATION_USER",
    "Broker",
    "BrokerURL",
    "mat_id_of",
    "mat_topic",
    "mqtt_client",
    "parse_broker_url",
    "read_mat_credentials",
    "station_broker",
]

#: The station's own user on its own broker.
STATION_USER = "texsense-station"
#: Names no mat may have: the station's user (a mat of that name would replace the station's
#: password and read every mat's frames).
RESERVED_IDS = frozenset({STATION_USER})
#: What a mat id (and so an MQTT user name, a topic segment, a URL segment and a folder name)
#: may be.
MAT_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")


@dataclass(frozen=True)
class BrokerURL:
    """Where a broker is and how to log in (passed through to paho): user name and password,
    TLS (``mqtts://``) with an optional CA file (default: the system's) and an optional client
    certificate and key."""

    host: str
    port: int
    username: str | None = None
    password: str | None = None
    tls: bool = False
    ca_file: str | None = None
    cert_file: str | None = None
    key_file: str | None = None

    def __str__(self) -> str:
        scheme = "mqtts" if self.tls else "mqtt"
        user = f"{self.username}@" if self.username else ""
        return f"{scheme}://{user}{self.host}:{self.port}"

    def login(self, username: str, password: str) -> BrokerURL:
        """The same broker with other credentials."""
        return replace(self, username=username, password=password)


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
        try:
            client.tls_set(
                ca_certs=broker.ca_file, certfile=broker.cert_file, keyfile=broker.key_file
            )
        except (OSError, ValueError) as e:  # ssl.SSLError is an OSError
            raise ParameterError(f"broker {broker}: cannot set up TLS: {e}") from None
    client.reconnect_delay_set(min_delay=1, max_delay=2)
    client.connect_async(broker.host, broker.port, keepalive=10)
    return client


def _die_with_parent() -> None:
    """In the child before exec (Linux): end with the parent, even one that is killed. (As
    root, Mosquitto drops to its own user at start, which clears this: a station killed with
    SIGKILL then leaves its broker running; Ctrl-C and SIGTERM stop it either way.) The child
    gets a process group of its own: a Ctrl-C on the terminal reaches the station alone,
    which disconnects first and then stops its broker (no "lost the broker" on a clean stop)."""

    os.setpgid(0, 0)
    with contextlib.suppress(OSError):  # not Linux: the parent's stop() is the only way
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _hash(password: str) -> str:
    """Mosquitto's password-file hash (``$7$``: PBKDF2-SHA512, 101 rounds, as
    ``mosquitto_passwd`` writes it)."""
    salt = secrets.token_bytes(12)
    digest = hashlib.pbkdf2_hmac("sha512", password.encode(), salt, 101)
    return f"$7$101${base64.b64encode(salt).decode()}${base64.b64encode(digest).decode()}"


def _mosquitto() -> str:
    exe = shutil.which("mosquitto") or next(
        (p for p in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto") if Path(p).exists()),
        None,
    )
    if exe is None:
        raise ParameterError(
            "Mosquitto is not installed: 'apt-get install mosquitto' (scripts/run.sh does "
            "it when run as root), or give a running broker with --broker mqtt://host:port"
        )
    return exe


class Broker:
    """A Mosquitto process listening on 127.0.0.1 only (no persistence), in a temporary
    folder that :meth:`stop` removes.

    Parameters
    ----------
    port : int, optional
        Default: a free port.
    users : dict of name -> password, optional
        Only these may connect (default: anyone, for tests that stand in for a site broker).
    acl : list of (user, access, topic), optional
        What each user may do: ``access`` is ``read``, ``write`` or ``readwrite``; nothing
        else is allowed. Default with ``users``: nothing at all.
    max_packet_bytes : int, optional
        A client that sends a larger packet is disconnected by the broker.
    """

    def __init__(
        self,
        port: int | None = None,
        *,
        users: dict[str, str] | None = None,
        acl: list[tuple[str, str, str]] | None = None,
        max_packet_bytes: int | None = None,
    ) -> None:
        self.exe = _mosquitto()
        self.port = port or _free_port()
        self.users = dict(users or {})
        self._dir = Path(tempfile.mkdtemp(prefix="texsense-broker-"))
        self.config = self._dir / "mosquitto.conf"
        lines = [f"listener {self.port} 127.0.0.1", "persistence false",
                 f"log_dest file {self._dir / 'mosquitto.log'}"]  # fmt: skip
        if max_packet_bytes:
            lines.append(f"max_packet_size {int(max_packet_bytes)}")
        if users is None:
            lines.append("allow_anonymous true")
        else:
            passwd = "".join(f"{u}:{_hash(p)}\n" for u, p in self.users.items())
            rules = "".join(f"user {u}\ntopic {a} {t}\n" for u, a, t in acl or [])
            (self._dir / "passwd").write_text(passwd, encoding="utf-8")
            (self._dir / "acl").write_text(rules, encoding="utf-8")
            # a client is known by its user name only: a mat that connects with another
            # mat's client id gets its own user's id (it cannot disconnect the other mat)
            lines += ["allow_anonymous false", f"password_file {self._dir / 'passwd'}",
                      f"acl_file {self._dir / 'acl'}", "use_username_as_clientid true"]  # fmt: skip
        self.config.write_text("\n".join(lines) + "\n", encoding="utf-8")
        self._own_files()
        self._proc: subprocess.Popen[bytes] | None = None

    def _own_files(self) -> None:
        """As root, Mosquitto drops to its own user before it reads the password file and
        opens its log: hand it the folder (still closed to everybody else)."""
        if os.geteuid() != 0:
            return

        try:
            user = pwd.getpwnam("mosquitto")
        except KeyError:
            return
        for parent in self._dir.parents:  # the user must be able to walk down to it
            info = parent.stat()
            if not info.st_mode & 0o001 and info.st_uid != user.pw_uid:
                shutil.rmtree(self._dir, ignore_errors=True)
                raise ParameterError(
                    f"Mosquitto runs as the user 'mosquitto', who cannot enter {parent}: set "
                    "TMPDIR to a folder others may enter (e.g. /tmp)"
                )
        for path in [self._dir, *self._dir.iterdir()]:
            os.chown(path, user.pw_uid, user.pw_gid)

    @property
    def url(self) -> BrokerURL:
        """Where clients connect (no credentials: see :meth:`BrokerURL.login`)."""
        return BrokerURL("127.0.0.1", self.port)

    def start(self, timeout_s: float = 10.0) -> Broker:
        """Start the process and wait until it accepts connections."""
        if self.running:
            return self
        if not self._dir.is_dir():
            raise ParameterError("this broker was stopped for good (its folder is removed)")
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
                self.pause()
                raise ParameterError(f"mosquitto exited at start: {text}")
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.2):
                    return self
            except OSError:
                time.sleep(0.05)
        self.pause()
        raise ParameterError(f"mosquitto did not accept connections on port {self.port}")

    @property
    def running(self) -> bool:
        """True while the process runs."""
        return self._proc is not None and self._proc.poll() is None

    def pause(self) -> None:
        """Stop the process but keep its folder (:meth:`start` starts it again)."""
        if self._proc is not None and self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(timeout=1.0)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        self._proc = None

    def stop(self) -> None:
        """Stop the process (clients see the connection drop) and remove its folder."""
        self.pause()
        shutil.rmtree(self._dir, ignore_errors=True)

    async def supervise(self, every_s: float = 0.25) -> None:
        """Restart the process whenever it dies (same port, users and rights: the clients
        reconnect and nothing else changes), until cancelled; one line each time, and waits
        that grow (to 30 s) while it will not start."""
        log = logging.getLogger("texsense.station")
        wait = every_s
        while True:
            await asyncio.sleep(wait)
            if self.running or not self._dir.is_dir():
                wait = every_s
                continue
            code = self._proc.returncode if self._proc is not None else None
            log.warning("the station's broker stopped (exit %s); restarting it", code)
            self._proc = None
            try:
                await blocking(self.start)
                log.warning("the station's broker runs again on port %d", self.port)
                wait = every_s
            except ParameterError as e:
                wait = min(30.0, max(1.0, wait * 2))
                log.warning("the station's broker did not start (%s); next try in %.0f s", e, wait)

    def __enter__(self) -> Broker:
        try:
            return self.start()
        except BaseException:
            self.stop()
            raise

    def __exit__(self, *exc: object) -> None:
        self.stop()


def mat_topic(topic_filter: str, mat_id: str) -> str:
    """The topic a mat publishes to under a station's filter (``texsense/+/frames`` ->
    ``texsense/bed12/frames``)."""
    parts = topic_filter.split("/")
    if parts.count("+") != 1 or "#" in parts or len(parts) < 2 or parts[-2:] != ["+", "frames"]:
        raise ParameterError(
            f"--mats {topic_filter!r}: with its own broker the station needs a filter "
            "PREFIX/+/frames (one '+', for the mat id)"
        )
    return "/".join([*parts[:-2], mat_id, "frames"])


def mat_id_of(topic: str) -> str | None:
    """The mat id of a frames topic (``.../<mat id>/frames``), None for other topics."""
    parts = topic.split("/")
    if len(parts) < 2 or parts[-1] != "frames" or not parts[-2]:
        return None
    return parts[-2]


def check_mat_id(mat_id: str) -> str:
    """``mat_id`` if it may be a mat id: letters, digits, ``.``, ``_``, ``-`` (at most 64,
    not starting with a sign)."""
    if not isinstance(mat_id, str) or not MAT_ID.match(mat_id):
        raise ParameterError(
            f"mat id {shown(mat_id, 80)}: use letters, digits, '.', '_' and '-' only (at most "
            "64, starting with a letter or digit)"
        )
    if mat_id.lower() in RESERVED_IDS:
        raise ParameterError(f"mat id {mat_id!r} is the station's own name on its broker")
    return mat_id


def read_mat_credentials(path: Path) -> dict[str, str]:
    """The mats' passwords in ``path`` (TOML: ``[mats]`` ``id = "password"``); empty when the
    file does not exist yet."""

    if not os.path.lexists(path):
        return {}
    try:
        doc = toml_loads(read_regular(path, "the mats' credentials"))
    except (OSError, ValueError) as e:  # not TOML, not UTF-8, nested too deeply
        raise FormatError(path, f"cannot read the mats' credentials: {e}") from None
    mats = doc.get("mats", {})
    if not isinstance(mats, dict) or not all(isinstance(v, str) for v in mats.values()):
        raise FormatError(path, 'expected a table [mats] of id = "password"')
    return dict(mats)


def _write_mat_credentials(path: Path, creds: dict[str, str]) -> None:

    text = (
        "# MQTT credentials of the mats for the broker of `texsense station` (keep private):\n"
        "# a mat logs in with its id as the user name and publishes to <prefix>/<id>/frames.\n"
        "[mats]\n" + "".join(f"{json.dumps(k)} = {json.dumps(v)}\n" for k, v in creds.items())
    )
    with atomic_path(path) as tmp:  # written privately, then renamed over the old one
        os.chmod(tmp, 0o600)
        tmp.write_text(text, encoding="utf-8")


def station_broker(
    topic_filter: str,
    mats: dict[str, str],
    virtual: dict[str, str],
    credentials_file: Path | None,
    max_packet_bytes: int,
) -> tuple[Broker, BrokerURL, dict[str, BrokerURL]]:
    """The station's own broker, started: every client logs in, each with its own rights.

    Parameters
    ----------
    topic_filter : str
        The station's subscription (``PREFIX/+/frames``); it may read that only.
    mats : dict of mat id -> topic
        The MQTT mats of the ward file: each may publish to its topic only; their passwords
        are kept in ``credentials_file`` (made when missing, mode 0600).
    virtual : dict of mat id -> topic
        The virtual mats: the same rights, new passwords at every start.
    credentials_file : Path, optional
        Where the MQTT mats' passwords are kept.
    max_packet_bytes : int
        Larger packets are refused by the broker.

    Returns
    -------
    (broker, station's login, each mat's login)
    """
    for mat_id in [*mats, *virtual]:
        check_mat_id(mat_id)
    kept = read_mat_credentials(credentials_file) if credentials_file is not None else {}
    missing = [m for m in mats if m not in kept]
    for m in missing:
        kept[m] = secrets.token_urlsafe(18)
    if credentials_file is not None and missing:
        _write_mat_credentials(credentials_file, kept)
    passwords = {STATION_USER: secrets.token_urlsafe(18)}
    passwords |= {m: kept[m] for m in mats}
    passwords |= {m: secrets.token_urlsafe(18) for m in virtual}
    acl = [(STATION_USER, "read", topic_filter)]
    acl += [(m, "write", t) for m, t in {**mats, **virtual}.items()]
    broker = Broker(users=passwords, acl=acl, max_packet_bytes=max_packet_bytes)
    try:
        broker.start()
    except BaseException:
        broker.stop()  # the folder with it
        raise
    logins = {m: broker.url.login(m, passwords[m]) for m in [*mats, *virtual]}
    return broker, broker.url.login(STATION_USER, passwords[STATION_USER]), logins
