"""What every web request to ``texsense monitor`` and ``texsense station`` passes through
(docs/monitor.md, "Security"), in one place for both servers.

:class:`Access` holds the rules; :class:`Guard` is the ASGI middleware that applies them to
every HTTP request and WebSocket handshake before any route sees it (so a new router cannot
forget them), and adds the security headers to every response:

- **Host**: a request must name this server: a loopback address or ``localhost`` when bound
  to loopback; also any IP address, this machine's name and the names given with
  ``--allow-host`` when bound beyond it. A page of another site whose name was re-pointed at
  127.0.0.1 (DNS rebinding) is refused (403).
- **Origin**: a browser names the page that makes a request; a page of another origin (another
  host or port, or ``null``) is refused on every route, WebSockets included (403), unless
  listed with ``--allow-origin``. Requests without an Origin (scripts, curl) pass.
  State-changing requests (POST, PUT, PATCH, DELETE) are also refused when the browser says
  they come from another site (``Sec-Fetch-Site``), Origin or not.
- **Token**: with a token, every request carries it (``Authorization: Bearer``, header
  ``X-Texsense-Token`` or ``?token=``), else 401. :func:`resolve_token` takes it from
  ``--token``, ``--token-file`` or the environment variable ``TEXSENSE_TOKEN``.
- **Bodies**: a request body larger than :data:`MAX_BODY` is refused (413) before it is read:
  by its ``Content-Length``, or, sent in chunks, as soon as it passes the limit.
- **Headers**: a Content-Security-Policy that allows scripts, styles and connections of this
  origin only and no framing (``frame-ancestors 'none'``, ``X-Frame-Options: DENY``),
  ``Referrer-Policy: no-referrer`` (a token in the address never leaks to another site),
  ``X-Content-Type-Options: nosniff`` and same-origin opener and resource policies.

:func:`serve_app` runs an app with uvicorn so that Ctrl-C and SIGTERM stop it within about a
second in every state (open WebSockets, no data flowing) and without tracebacks;
:func:`stream` sends texts to a WebSocket until the viewer leaves.

Examples
--------
>>> access = Access(token=None, bind="127.0.0.1")
>>> access.host_ok("127.0.0.1:8765"), access.host_ok("localhost"), access.host_ok("evil.example")
(True, True, False)
>>> access.origin_ok("http://127.0.0.1:8765", "127.0.0.1:8765")
True
>>> access.origin_ok("http://localhost:9000", "127.0.0.1:8765")
False
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import gc
import hmac
import ipaddress
import json
import logging
import os
import re
import signal
import socket
import sys
import time
from collections.abc import Awaitable, Callable, Iterable, Iterator
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs

from texsense._progress import STOPPING, StoppingError, check_stopping
from texsense.data.files import json_loads, read_small_text, real_path
from texsense.exceptions import FormatError, ParameterError, shown
from texsense.monitor.sources import blocking

__all__ = [
    "MAX_BODY",
    "Access",
    "Guard",
    "Lane",
    "finish",
    "is_loopback",
    "plain_errors",
    "resolve_token",
    "safe_file",
    "serve_app",
    "stop_on_sigterm",
    "stream",
]

log = logging.getLogger("texsense.web")

#: Environment variable that can hold the token (instead of ``--token`` on the command line,
#: where every user of the machine can read it in the process list).
TOKEN_ENV = "TEXSENSE_TOKEN"
#: Methods that change state: refused from other origins and sites.
UNSAFE_METHODS = frozenset({"POST", "PUT", "PATCH", "DELETE"})
#: Longest a server waits for open requests when told to stop, s.
SHUTDOWN_S = 1.0
#: The largest request body any route takes, bytes (the regions of a recording are the
#: largest, 256 KiB); larger bodies are refused before they are read.
MAX_BODY = 1 << 20

_CSP = (
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
    "connect-src 'self' ws://{host} wss://{host}; frame-ancestors 'none'; base-uri 'none'; "
    "form-action 'self'"
)
#: FastAPI's /docs and /redoc pages load Swagger UI / ReDoc from a CDN with inline scripts.
_CSP_DOCS = (
    "default-src 'none'; script-src 'self' 'unsafe-inline' https://cdn.jsdelivr.net; "
    "style-src 'self' 'unsafe-inline' https://cdn.jsdelivr.net https://fonts.googleapis.com; "
    "font-src https://fonts.gstatic.com; img-src 'self' data: https://fastapi.tiangolo.com "
    "https://cdn.redoc.ly; connect-src 'self'; worker-src blob:; frame-ancestors 'none'; "
    "base-uri 'none'"
)
#: A report (texsense.apps.report) is a document of its own: its styles inline, its figures in
#: ``data:`` images, no script at all.
_CSP_REPORT = (
    "default-src 'none'; style-src 'unsafe-inline'; img-src data:; frame-ancestors 'none'; "
    "base-uri 'none'; form-action 'none'"
)
_HEADERS = [
    (b"x-frame-options", b"DENY"),
    (b"referrer-policy", b"no-referrer"),
    (b"x-content-type-options", b"nosniff"),
    (b"cross-origin-opener-policy", b"same-origin"),
    (b"cross-origin-resource-policy", b"same-origin"),
]


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``."""
    if host.lower().rstrip(".") == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def _is_ip(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


def host_name(host: str) -> str:
    """The name part of a Host header or an origin's network location (no port, no brackets,
    lower case): ``[::1]:8765`` -> ``::1``. What is not a name with an optional port of digits
    (``127.0.0.1:80.evil.example``, ``[::1``, ``localhost:abc``) is ``""``, which no server
    is named."""
    host = host.strip().lower()
    port = ""
    if host.startswith("["):
        end = host.find("]")
        if end < 0:
            return ""
        host, rest = host[1:end], host[end + 1 :]
        if rest and not rest.startswith(":"):
            return ""
        port = rest[1:] if rest else ""
    elif host.count(":") == 1:
        host, port = host.split(":", 1)
    if port and not (port.isascii() and port.isdigit()):
        return ""
    return host.rstrip(".")


#: An origin as browsers send it (RFC 6454, serialised): a lower-case scheme and host, no
#: user, path, query, fragment, space or trailing dot or slash; a port of digits.
_ORIGIN = re.compile(
    r"(?P<scheme>https?)://(?P<host>\[[0-9a-f:.]+\]|[a-z0-9](?:[a-z0-9.-]*[a-z0-9])?)"
    r"(?::(?P<port>[1-9][0-9]{0,4}))?"
)
_DEFAULT_PORT = {"http": 80, "https": 443}


def parse_origin(text: str) -> tuple[str, str, int] | None:
    """``(scheme, host, port)`` of an ``Origin`` header exactly as a browser serialises it
    (``http://127.0.0.1:8765``; the default port may be left out), else None: the one parser
    of origins of both servers, for the header and for ``--allow-origin``. Nothing is
    stripped or lowered: a space around it, a trailing slash or dot, a user, a path, upper
    case, ``null``, a port beyond 65535 or with a leading zero are not origins a browser
    sends, so they are no origin this server trusts.

    >>> parse_origin("http://127.0.0.1:8765"), parse_origin("https://portal.example")
    (('http', '127.0.0.1', 8765), ('https', 'portal.example', 443))
    >>> parse_origin("http://127.0.0.1:8765 "), parse_origin("null")
    (None, None)
    """
    m = _ORIGIN.fullmatch(text)
    if m is None:
        return None
    host = m["host"]
    if host.startswith("["):
        try:
            ipaddress.IPv6Address(host[1:-1])
        except ValueError:
            return None
    port = int(m["port"]) if m["port"] else _DEFAULT_PORT[m["scheme"]]
    if port > 65535:
        return None
    return m["scheme"], host.strip("[]"), port


def host_port(host: str, default: int = 80) -> tuple[str, int] | None:
    """``(name, port)`` of a Host header (:func:`host_name`, the port ``default`` when none
    is given), None when it is no name with an optional port."""
    name = host_name(host)
    if not name:
        return None
    rest = host.strip().rsplit("]", 1)[-1] if host.strip().startswith("[") else host.strip()
    port = rest.rsplit(":", 1)[1] if rest.count(":") == 1 else ""
    if port and not (port.isascii() and port.isdigit() and 0 < int(port) <= 65535):
        return None
    return name, int(port) if port else default


def safe_file(folder: Path, name: str) -> Path | None:
    """``folder / name`` if it is a plain file inside ``folder`` (no traversal), else None."""
    if not name or "/" in name or "\\" in name or name.startswith(".") or "\x00" in name:
        return None
    base = real_path(folder)
    path = real_path(base / name)
    try:
        if path.parent != base or not path.is_file():
            return None
    except OSError:  # a name the file system refuses (too long, ...): no such file
        return None
    return path


def resolve_token(
    token: str | None = None,
    token_file: str | Path | None = None,
    env: Any = None,
    option: str = "--token-file",
) -> str | None:
    """The token from ``--token``, else ``--token-file`` (its first line), else the
    environment variable :data:`TOKEN_ENV`; None when none is given. ``option`` names the
    file's option in the errors (the station's ``--broker-password-file`` reads its password
    the same way).

    Raises
    ------
    ParameterError
        Both ``--token`` and ``--token-file``, an unreadable or empty token file, or a token
        shorter than 8 characters.
    """
    env = os.environ if env is None else env
    if token is not None and token_file is not None:
        raise ParameterError("give the token once: --token or --token-file, not both")
    where = "--token"
    if token_file is not None:
        path = Path(token_file)
        text = read_small_text(path, option, limit=4096)  # not /dev/zero, nor a FIFO
        token = text.strip().splitlines()[0].strip() if text.strip() else ""
        where = f"{option} {path}"
    elif token is None and env.get(TOKEN_ENV):
        token, where = env[TOKEN_ENV].strip(), f"${TOKEN_ENV}"
    if token is None:
        return None
    if len(token) < 8 or any(c.isspace() for c in token):
        raise ParameterError(f"{where}: a token needs at least 8 characters and no spaces")
    return token


def _allowed_origin(text: str) -> tuple[str, str, int]:
    """An ``--allow-origin`` URL (a trailing slash allowed) as :func:`parse_origin` gives it;
    anything else is a :class:`~texsense.exceptions.ParameterError`."""
    parsed = parse_origin(text.strip().removesuffix("/"))
    if parsed is None:
        raise ParameterError(
            f"--allow-origin {shown(text, 80)}: expected an origin as a browser sends it, "
            "scheme://host[:port] in lower case (e.g. https://portal.example)"
        )
    return parsed


class Access:
    """The rules of :class:`Guard`: who may ask what.

    Parameters
    ----------
    token : str, optional
        Required on every request when given.
    bind : str
        The address the server listens on: loopback (the default) admits loopback Host names
        only; beyond loopback, IP addresses and this machine's names are admitted too.
    hosts : iterable of str
        More Host names to admit (``--allow-host``: a DNS name of the station, a reverse
        proxy's name).
    origins : iterable of str
        More page origins to admit (``--allow-origin https://portal.example``).
    """

    def __init__(
        self,
        token: str | None = None,
        bind: str = "127.0.0.1",
        hosts: Iterable[str] = (),
        origins: Iterable[str] = (),
    ) -> None:
        self.token = token
        self.bind = bind
        self.loopback = is_loopback(bind)
        self.hosts = {host_name(h) for h in hosts}
        if not self.loopback:
            self.hosts |= {host_name(socket.gethostname()), host_name(socket.getfqdn())}
        self.origins = {_allowed_origin(o) for o in origins}

    def host_ok(self, host: str) -> bool:
        """Whether a Host header names this server."""
        name = host_name(host)
        if not name:
            return False
        if is_loopback(name) or name in self.hosts:
            return True
        return not self.loopback and _is_ip(name)

    def origin_ok(self, origin: str, host: str) -> bool:
        """Whether a page of ``origin`` may talk to this server reached as ``host``: an
        origin (:func:`parse_origin`, strictly) listed with ``--allow-origin``, or this
        server's own: ``http`` (the servers speak plain HTTP; a page of ``https://`` is another
        origin) with the Host header's name and port."""
        parsed = parse_origin(origin)
        if parsed is None:
            return False
        if parsed in self.origins:
            return True
        own = host_port(host)
        return own is not None and parsed == ("http", *own)

    def token_ok(self, headers: dict[str, str], query: str) -> bool:
        """The token rule: ``?token=``, ``X-Texsense-Token`` or a bearer header."""
        if self.token is None:
            return True
        given = (parse_qs(query).get("token") or [""])[0] or headers.get("x-texsense-token", "")
        auth = headers.get("authorization", "")
        if not given and auth.lower().startswith("bearer "):
            given = auth[7:]
        return hmac.compare_digest(given.encode(), self.token.encode())

    def check(self, method: str, headers: dict[str, str], query: str) -> tuple[int, str] | None:
        """None when the request may pass, else (HTTP status, reason)."""
        host = headers.get("host", "")
        if not self.host_ok(host):
            return 403, f"unknown Host {shown(host, 80)}: this server answers to its own address " \
                "(add a name with --allow-host)"  # fmt: skip
        origin = headers.get("origin")
        if origin is not None and not self.origin_ok(origin, host):
            return 403, f"cross-origin request from {shown(origin, 80)} refused"
        site = headers.get("sec-fetch-site", "")
        if method in UNSAFE_METHODS and site in ("cross-site", "same-site"):
            return 403, f"a {site} {method} is refused"
        if not self.token_ok(headers, query):
            return 401, "missing or wrong token"
        return None


class Guard:
    """ASGI middleware: :meth:`Access.check` on every HTTP request and WebSocket handshake,
    the security headers on every HTTP response (add it with
    ``app.add_middleware(Guard, access=...)``)."""

    def __init__(self, app: Any, access: Access) -> None:
        self.app = app
        self.access = access
        self._logged: dict[str, float] = {}

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        kind = scope["type"]
        if kind not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}
        method = scope.get("method", "GET") if kind == "http" else "GET"
        refused = self.access.check(method, headers, scope.get("query_string", b"").decode())
        if refused is not None:
            self._log(refused[1], scope, method)
            if kind == "websocket":
                await send({"type": "websocket.close", "code": 4000 + refused[0]})
                return
            await self._refuse(send, refused, headers.get("host", ""))
            return
        if kind == "websocket":
            await self.app(scope, receive, send)
            return
        receive = await self._bounded(headers, receive, send)
        if receive is None:
            return
        policy = _csp(scope.get("path", ""), headers.get("host", ""))

        async def send_with_headers(message: dict[str, Any]) -> None:
            if message["type"] == "http.response.start":
                message["headers"] = [*message.get("headers", []), *policy]
            await send(message)

        await self.app(scope, receive, send_with_headers)

    async def _bounded(self, headers: dict[str, str], receive: Any, send: Any) -> Any:
        """``receive`` for a body within :data:`MAX_BODY` that is JSON (read here, checked by
        :func:`texsense.data.files.json_loads`, then handed on), or None once a body is
        refused: larger (413, by its ``Content-Length`` before it is read), or not JSON, with a
        key twice, nested too deeply or a number beyond any float (400, as the routes answer text
        that is not JSON). Every body of both servers is JSON, so this is
        the one parser every body meets before a route reads it again."""
        host = headers.get("host", "")
        too_big = (413, f"the request body is larger than {MAX_BODY // 1024} KiB")
        length = headers.get("content-length")
        if length is not None:
            if not length.strip().isdigit() or int(length) > MAX_BODY:
                await self._refuse(send, too_big, host)
                return None
        elif "chunked" not in headers.get("transfer-encoding", ""):
            return receive
        chunks, size = [], 0
        while True:
            message = await receive()
            if message["type"] != "http.request":
                return _replay_then(message, receive)  # gone before the body ended
            chunks.append(message.get("body", b""))
            size += len(chunks[-1])
            if size > MAX_BODY:
                await self._refuse(send, too_big, host)
                return None
            if not message.get("more_body", False):
                break
        body = b"".join(chunks)
        if body.strip():
            try:
                json_loads(body)
            except (ValueError, UnicodeDecodeError) as e:
                await self._refuse(send, (400, f"the request body is not JSON: {e}"[:300]), host)
                return None
        return _replay_then({"type": "http.request", "body": body, "more_body": False}, receive)

    async def _refuse(self, send: Any, refused: tuple[int, str], host: str) -> None:
        status, reason = refused
        body = json.dumps({"detail": reason}).encode()
        head = [(b"content-type", b"application/json"), (b"content-length", b"%d" % len(body))]
        head += _csp("", host)
        await send({"type": "http.response.start", "status": status, "headers": head})
        await send({"type": "http.response.body", "body": body})

    def _log(self, reason: str, scope: dict[str, Any], method: str) -> None:
        """One console line per kind of refusal and minute (a page that retries does not fill
        the log)."""
        now = time.monotonic()
        key = f"{scope['type']} {method} {reason[:40]}"
        if now - self._logged.get(key, -1e9) >= 60.0:
            self._logged[key] = now
            if len(self._logged) > 1000:
                self._logged.clear()
            client = scope.get("client") or ("?", 0)
            what = "WebSocket" if scope["type"] == "websocket" else method
            log.warning("refused %s %s from %s: %s", what, scope.get("path", ""), client[0], reason)


def _replay_then(first: dict[str, Any], receive: Any) -> Any:
    """A ``receive`` that gives ``first`` once, then what ``receive`` gives."""
    done = False

    async def replay() -> dict[str, Any]:
        nonlocal done
        if done:
            return dict(await receive())
        done = True
        return first

    return replay


def _csp(path: str, host: str) -> list[tuple[bytes, bytes]]:
    safe_host = "".join(c for c in host if c.isalnum() or c in ".-:[]") or "localhost"
    if path.endswith(("/docs", "/redoc", "/docs/oauth2-redirect")):
        policy = _CSP_DOCS
    elif path.endswith("/report"):
        policy = _CSP_REPORT
    else:
        policy = _CSP.format(host=safe_host)
    return [(b"content-security-policy", policy.encode()), *_HEADERS]


async def finish(tasks: list[asyncio.Task[Any]]) -> None:
    """Cancel ``tasks`` and wait for them (their cancellation is no error; an error of theirs
    was reported where it happened)."""
    for t in tasks:
        t.cancel()
    for t in tasks:
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await t


async def stream(
    websocket: Any, first: str | None, next_text: Callable[[], Awaitable[str]]
) -> None:
    """Accept ``websocket``, send ``first`` (if any) and then each text ``next_text()`` gives,
    until the viewer leaves or the server stops. It listens for the viewer's departure while it
    waits, so a closed browser tab ends it at once even when no data is flowing."""
    from starlette.websockets import WebSocketDisconnect

    await websocket.accept()
    gone = asyncio.ensure_future(_until_disconnect(websocket))
    try:
        if first is not None:
            await websocket.send_text(first)
        while True:
            text = asyncio.ensure_future(next_text())
            done, _ = await asyncio.wait({text, gone}, return_when=asyncio.FIRST_COMPLETED)
            if gone in done:
                text.cancel()
                return
            await websocket.send_text(text.result())
    except (WebSocketDisconnect, RuntimeError, ConnectionError):
        return
    finally:
        gone.cancel()


async def _until_disconnect(websocket: Any) -> None:
    while True:
        message = await websocket.receive()
        if message["type"] == "websocket.disconnect":
            return


def plain_errors(app: Any) -> Any:
    """Answer a request whose parameters or body do not validate with 422 and one line (where
    and what), never echoing the input: FastAPI's own answer repeats it and fails on a value
    JSON cannot hold (``{"frames": NaN}`` was a 500). A ``ParameterError`` or ``FormatError``
    that no route turned into its own answer is a 422 with its line too (a parameter the event
    store cannot hold, ``?session=99999999999999999999999``, was a 500). Every app of both
    servers calls this."""
    from fastapi.exceptions import RequestValidationError
    from fastapi.responses import JSONResponse

    async def invalid(_request: Any, exc: Exception) -> Any:
        errors = exc.errors() if isinstance(exc, RequestValidationError) else []
        first = errors[0] if errors else {}
        where = ".".join(str(p) for p in first.get("loc", ()) if p != "body") or "body"
        text = str(first.get("msg", "invalid request"))[:200]
        return JSONResponse({"detail": f"{where}: {text}"}, status_code=422)

    async def refused(_request: Any, exc: Exception) -> Any:
        return JSONResponse({"detail": str(exc)[:300]}, status_code=422)

    app.add_exception_handler(RequestValidationError, invalid)
    app.add_exception_handler(ParameterError, refused)
    app.add_exception_handler(FormatError, refused)
    return app


class Lane:
    """Where a server runs one kind of slow work (reading a recording for playback, fitting a
    calibration): at most ``workers`` calls at once, each in a daemon thread, and at most
    ``waiting`` more queued; beyond that a call is refused at once (503) instead of waiting.
    A call that never returns (a file that does not answer) holds its own lane only: the
    live feed, the other lanes and a stop (SIGTERM: daemon threads are not waited for) go on.

    Parameters
    ----------
    name : str
        What the lane does, for the refusal (``playback``).
    workers, waiting : int
        Calls at once, and queued.
    """

    def __init__(self, name: str, workers: int = 2, waiting: int = 8) -> None:
        self.name = name
        self.workers = workers
        self.waiting = waiting
        self._slots: asyncio.Semaphore | None = None
        self._queued = 0

    async def run(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """``fn(*args, **kwargs)`` in a daemon thread of this lane; its result or error."""
        from fastapi import HTTPException

        if self._slots is None:
            self._slots = asyncio.Semaphore(self.workers)
        if STOPPING.is_set():
            raise HTTPException(503, "the server is stopping")
        if self._queued >= self.workers + self.waiting:
            raise HTTPException(503, f"{self.name} is busy: try again in a moment")
        self._queued += 1
        try:
            async with self._slots:
                check_stopping()  # waited while the server was told to stop
                return await blocking(functools.partial(fn, *args, **kwargs))
        except StoppingError:  # the server stops: the work was dropped (texsense._progress)
            raise HTTPException(503, "the server is stopping") from None
        finally:
            self._queued -= 1


def _cut_short(record: logging.LogRecord) -> bool:
    """False for uvicorn's report of a request it cancelled because the server stops (a
    request still waiting when the grace period ends): an expected end, not an error."""
    exc = record.exc_info[1] if record.exc_info else None
    return not isinstance(exc, asyncio.CancelledError)


def _server_class() -> Any:
    import uvicorn

    logging.getLogger("uvicorn.error").addFilter(_cut_short)

    class Server(uvicorn.Server):
        """uvicorn's server, but a signal only stops it (uvicorn would re-raise SIGTERM
        after its shutdown, which ends the process before the caller can clean up: its
        broker, its temporary folder)."""

        signal_received: int | None = None

        @contextlib.contextmanager
        def capture_signals(self) -> Iterator[None]:
            def stop(sig: int, _frame: Any) -> None:
                self.signal_received = sig
                STOPPING.set()  # the workers' long loops end (texsense._progress)
                if self.should_exit:
                    # a second Ctrl-C: stop waiting for anything, and say so in one line
                    # instead of the tracebacks of the tasks uvicorn then cancels
                    self.force_exit = True
                    logging.getLogger("uvicorn.error").setLevel(logging.CRITICAL)
                    print("texsense: stopping now (second signal)", file=sys.stderr, flush=True)
                self.should_exit = True

            previous = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
            try:
                yield
            finally:
                for s, handler in previous.items():
                    signal.signal(s, handler)

    return Server


def serve_app(app: Any, host: str, port: int) -> int | None:
    """Run ``app`` until Ctrl-C or SIGTERM; returns the signal that stopped it (None if it
    stopped by itself). Open connections get :data:`SHUTDOWN_S` to finish."""
    import uvicorn

    config = uvicorn.Config(
        app,
        host=host,
        port=port,
        log_level="warning",
        timeout_graceful_shutdown=SHUTDOWN_S,  # type: ignore[arg-type]  # a float works
        proxy_headers=False,
        server_header=False,
    )
    server = _server_class()(config)
    # Everything made so far (modules, models, calibrations) lives as long as the process: out
    # of the collector's sight it costs no collection pauses, and the interpreter's teardown
    # after a stop takes 0.1 s instead of 0.7 s (scipy, scikit-learn).
    gc.freeze()
    server.run()
    return server.signal_received


@contextlib.contextmanager
def stop_on_sigterm() -> Iterator[None]:
    """While a command sets up (before its server handles signals), SIGTERM raises
    KeyboardInterrupt like Ctrl-C, so that its clean-up (a broker, temporary files) runs."""

    def interrupt(_sig: int, _frame: Any) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
