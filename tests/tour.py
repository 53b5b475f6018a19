"""The tour runner: every ``console`` block of the README and of docs/*.md runs as written.

Rules (also in docs/development.md):

- A page's blocks run in order, in one fresh folder of their own that holds only ``.venv``
  (a link to the repository's) and, one level up, ``shared`` (a link to the real data), so
  that ``.venv/bin/texsense ...`` and ``../shared/data/...`` work as written; ``bash
  scripts/...`` and ``benchmarks/...`` are linked in too.
- ``$ `` starts a command (a line ending in ``\\`` continues it); the lines after it, up to
  the next command, are its expected output, compared as doctest does (``...`` matches
  anything, whitespace runs are equal). A command with no output shown only has to succeed.
- Servers (``texsense monitor``, ``texsense station``, ``texsense simulate device``, ``bash
  scripts/run.sh``) start in the background; the runner waits until they answer (their
  page, or the device's link) and stops them with Ctrl-C (SIGINT) at the end of the
  block, or (a monitor, station or run.sh) before the next one of the block starts; a
  virtual device runs on to the end of its block, for the monitors that read it. The one
  thing the runner changes in a command: a monitor or station gets a free ``--port`` (in
  place of one the page names: tests and people run side by side), and the later commands
  of its block that name the page's port (``localhost:8790``) get the free one.
- A command with a trailing comment ``# needs: ...`` (outside hardware, a site broker, a
  cluster) is skipped and listed with its reason.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import doctest
import os
import re
import signal
import socket
import subprocess
import tempfile
import threading
import time
import urllib.request
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BLOCK = re.compile(r"^```console\n(.*?)^```", re.DOTALL | re.MULTILINE)
NEEDS = re.compile(r"#\s*needs:\s*(.+)$")
SERVERS = (
    re.compile(r"(^|\s)(\S*texsense)\s+(monitor|station)(\s|$)"),
    re.compile(r"(^|\s)(\S*texsense)\s+simulate\s+device(\s|$)"),
    re.compile(r"(^|\s)bash\s+scripts/run\.sh(\s|$)"),
)
_CHECKER = doctest.OutputChecker()
_FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


@dataclass
class Command:
    """One ``$`` line of a page (continuations joined) and the output the page shows."""

    page: str
    block: int
    text: str
    expected: str = ""

    @property
    def needs(self) -> str | None:
        """Why it cannot run here (a ``# needs:`` comment), else None."""
        m = NEEDS.search(self.text)
        return m.group(1).strip() if m else None

    @property
    def is_server(self) -> bool:
        """Whether it runs until stopped."""
        return any(p.search(self.text) for p in SERVERS)


@dataclass
class Outcome:
    """What happened to the commands of one page."""

    ran: list[str] = field(default_factory=list)
    skipped: list[tuple[str, str]] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)
    seconds: float = 0.0
    timed: list[tuple[float, str]] = field(default_factory=list)  # (s, command) of each


def commands(page: Path) -> list[Command]:
    """The commands of ``page``, in order."""
    out: list[Command] = []
    for k, body in enumerate(BLOCK.findall(page.read_text(encoding="utf-8"))):
        current: Command | None = None
        lines = iter(body.splitlines())
        for line in lines:
            if line.startswith("$ "):
                text = line[2:]
                while text.endswith("\\"):
                    text = text[:-1] + " " + next(lines, "").strip()
                current = Command(page.name, k, text)
                out.append(current)
            elif current is not None:
                current.expected += line + "\n"
    return out


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _prepare(folder: Path, shared: Path) -> Path:
    """The fresh folder ``folder/work`` beside ``folder/shared``."""
    work = folder / "work"
    work.mkdir(parents=True)
    (folder / "shared").symlink_to(shared.resolve())
    for name in (".venv", "scripts", "benchmarks"):
        (work / name).symlink_to(ROOT / name)
    return work


class _Server:
    def __init__(self, cmd: Command, work: Path, env: dict[str, str]) -> None:
        text = cmd.text
        self.port: int | None = None
        self.named_port: str | None = None
        if re.search(r"texsense\s+(monitor|station)|scripts/run\.sh", text):
            # a free port, in place of the one the page names (tests and people run side by side)
            named = re.search(r"\s--port[ =](\d+)", text)
            self.named_port = named.group(1) if named else None
            self.port = _free_port()
            text = re.sub(r"\s--port[ =]\d+", "", _strip_comment(text)) + f" --port {self.port}"
        self.link = None
        m = re.search(r"--link[ =](\S+)", text)
        if m:
            self.link = work / m.group(1)
        self.cmd = cmd
        self.log = work / f".tour-server-{time.monotonic_ns()}.log"
        with self.log.open("wb") as log:
            self.proc = subprocess.Popen(
                ["bash", "-c", "exec " + text],
                cwd=work,
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )

    def ready(self, timeout: float = 180.0) -> str | None:
        """None once it answers; else what went wrong."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                return f"exited with {self.proc.returncode} before it was ready"
            if self.port is not None:
                try:
                    url = f"http://127.0.0.1:{self.port}/"
                    with urllib.request.urlopen(url, timeout=2) as r:
                        if r.status == 200:
                            return None
                except OSError:
                    pass
            elif self.link is not None and self.link.exists():
                return None
            time.sleep(0.2)
        return f"not ready after {timeout:.0f} s"

    def stop(self) -> str | None:
        """Ctrl-C; None if it stopped cleanly within 10 s."""
        if self.proc.poll() is not None:
            return f"had exited with {self.proc.returncode}"
        os.killpg(self.proc.pid, signal.SIGINT)
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
            return "did not stop within 30 s of Ctrl-C"
        if "Traceback" in self.output():
            return "printed a traceback"
        return None

    def output(self) -> str:
        return self.log.read_text(errors="replace")

    @property
    def is_device(self) -> bool:
        """A virtual device: what a monitor of the same block reads, so it stays when the
        next monitor starts."""
        return re.search(r"simulate\s+device", self.cmd.text) is not None


def _strip_comment(text: str) -> str:
    """The command without a trailing ``# comment`` (a ``#`` after a space, outside quotes)."""
    quote = None
    for i, ch in enumerate(text):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (i == 0 or text[i - 1].isspace()):
            return text[:i].rstrip()
    return text


def run_page(
    page: Path,
    folder: Path,
    shared: Path,
    *,
    timeout: float = 900.0,
    base_env: Mapping[str, str] | None = None,
    cancel: threading.Event | None = None,
) -> Outcome:
    """Run every command of ``page`` in a fresh folder under ``folder``, with the environment
    ``base_env`` (default: this process's, as it is when the page starts); ``cancel`` set:
    no further command starts, the servers stop."""
    started = time.monotonic()
    work = _prepare(folder, shared)
    env = dict(os.environ if base_env is None else base_env)
    env.update(TEXSENSE_NO_PROGRESS="1", COLUMNS="100")
    env.pop("PYTEST_CURRENT_TEST", None)
    outcome = Outcome()
    servers: list[_Server] = []
    block = -1

    def stop_servers(keep_devices: bool = False) -> None:
        for s in list(servers):
            if keep_devices and s.is_device:
                continue
            why = s.stop()
            if why:
                outcome.failures.append(f"{s.cmd.text}\n  {why}\n{s.output()[-2000:]}")
            servers.remove(s)

    moved: dict[str, int] = {}  # the ports a page names -> the free ones its servers got
    for cmd in commands(page):
        if cancel is not None and cancel.is_set():
            outcome.failures.append("cancelled before: " + cmd.text)
            break
        if cmd.block != block:
            stop_servers()
            block = cmd.block
            moved = {}
        for named, port in moved.items():  # later commands reach the server where it runs
            cmd.text = re.sub(rf"(localhost|127\.0\.0\.1):{named}\b", rf"\g<1>:{port}", cmd.text)
        if cmd.needs:
            outcome.skipped.append((cmd.text, cmd.needs))
            continue
        began = time.monotonic()
        if cmd.is_server:
            if not re.search(r"simulate\s+device", cmd.text):
                stop_servers(keep_devices=True)  # alternatives of one block: one at a time
            server = _Server(cmd, work, env)
            servers.append(server)
            if server.named_port is not None and server.port is not None:
                moved[server.named_port] = server.port
            why = server.ready()
            outcome.ran.append(cmd.text)
            outcome.timed.append((time.monotonic() - began, cmd.text))
            if why:
                outcome.failures.append(f"{cmd.text}\n  {why}\n{server.output()[-3000:]}")
            continue
        proc = subprocess.run(
            ["bash", "-c", cmd.text],
            cwd=work,
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
        )
        outcome.ran.append(cmd.text)
        outcome.timed.append((time.monotonic() - began, cmd.text))
        if proc.returncode != 0:
            outcome.failures.append(
                f"{cmd.text}\n  exit {proc.returncode}\n{proc.stderr[-3000:]}{proc.stdout[-1000:]}"
            )
        elif cmd.expected.strip() and not _CHECKER.check_output(
            cmd.expected, proc.stdout + proc.stderr, _FLAGS
        ):
            outcome.failures.append(
                f"{cmd.text}\n  output differs from the page:\n--- page\n{cmd.expected}"
                f"--- got\n{proc.stdout}{proc.stderr}"
            )
    stop_servers()
    outcome.seconds = time.monotonic() - started
    return outcome


def run_pages(
    pages: list[Path],
    folder: Path,
    shared: Path,
    *,
    jobs: int = 2,
    base_env: Mapping[str, str] | None = None,
) -> dict[Path, Outcome]:
    """Run ``pages`` (each in a folder of its own under ``folder``), ``jobs`` at a time: a
    page waits mostly on servers starting and child processes, and the pages share nothing
    (every monitor and station gets a free port), so two lanes halve the tour's wall time.
    The pages start in the order given (put the longest first)."""
    return start_pages(pages, folder, shared, jobs=jobs, base_env=base_env).result()


def start_pages(
    pages: list[Path],
    folder: Path,
    shared: Path,
    *,
    jobs: int = 2,
    base_env: Mapping[str, str] | None = None,
    cancel: threading.Event | None = None,
) -> concurrent.futures.Future:
    """:func:`run_pages` in the background: a future of its result (the test suite starts
    the tour first and runs its other tests meanwhile); ``cancel`` stops it early."""
    done: concurrent.futures.Future = concurrent.futures.Future()

    def tour() -> None:
        try:
            with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
                futures = {
                    page: pool.submit(
                        run_page,
                        page,
                        folder / f"{k:02d}-{page.stem}",
                        shared,
                        base_env=base_env,
                        cancel=cancel,
                    )
                    for k, page in enumerate(pages)
                }
                done.set_result({page: f.result() for page, f in futures.items()})
        except BaseException as e:  # the test that waits for it reports it
            done.set_exception(e)

    threading.Thread(target=tour, name="tour", daemon=True).start()
    return done


def main(argv: list[str] | None = None) -> int:
    """``python tests/tour.py [PAGE.md ...]``: run the pages (default: the README and every
    docs page), print per page what ran, was skipped and failed, and the time taken."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("pages", nargs="*", type=Path, help="pages (default: all)")
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared", help="data root")
    parser.add_argument("--jobs", type=int, default=2, help="pages run at a time (2)")
    args = parser.parse_args(argv)
    pages = args.pages or [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    start = time.monotonic()
    with tempfile.TemporaryDirectory() as folder:
        outcomes = run_pages(
            [p for p in pages if commands(p)], Path(folder), args.shared, jobs=args.jobs
        )
    print("| page | commands run | passed | skipped (needs) | time |")
    print("|---|---:|---:|---:|---:|")
    for page, o in outcomes.items():
        passed = sum(1 for text in o.ran if not any(f.startswith(text) for f in o.failures))
        print(f"| {page.name} | {len(o.ran)} | {passed} | {len(o.skipped)} | {o.seconds:.1f} s |")
    failed = 0
    for page, o in outcomes.items():
        for text, why in o.skipped:
            print(f"{page.name}: skipped (needs {why}): {text}")
        for text in o.failures:
            failed += 1
            print(f"{page.name}: FAILED: " + text.replace("\n", "\n    "))
    slowest = sorted((t, p.name, c) for p, o in outcomes.items() for t, c in o.timed)[-10:]
    print("\nslowest commands (to the server's first answer):")
    for t, name, text in reversed(slowest):
        print(f"  {t:6.1f} s  {name}: {text[:90]}")
    print(f"\ntotal {time.monotonic() - start:.1f} s ({args.jobs} at a time), {failed} failure(s)")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
