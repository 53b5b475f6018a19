"""The ``texsense`` command line: one sub-command per entry of :data:`texsense.commands.COMMANDS`.

Only the module of the command that runs is imported (``texsense --version`` and ``--help``
import none of them, nor numpy's heavier neighbours: benchmarks/cli_start.py measures it).

Exit codes: 0 ok, 1 failed (bad file, bad data), 2 bad usage.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import os
import signal
import sys
import threading
import warnings
from collections.abc import Callable, Collection, Iterator, Sequence
from typing import TYPE_CHECKING, Any

from texsense._core import __version__
from texsense.commands import COMMANDS
from texsense.commands._applies import check_given
from texsense.commands._options import check_numbers, check_words
from texsense.exceptions import FormatError, ParameterError, UnitError, WriteError

if TYPE_CHECKING:
    from types import FrameType

__all__ = ["build_parser", "main"]


def _command_of(argv: Sequence[str]) -> str | None:
    """The command named in ``argv`` (its first word that is not an option), if any."""
    for word in argv:
        if not word.startswith("-"):
            return word if word in COMMANDS else None
    return None


def build_parser(commands: Collection[str] = ()) -> argparse.ArgumentParser:
    """The argument parser: every command listed, with the options of ``commands`` (their
    modules imported; ``build_parser(COMMANDS)`` loads them all)."""
    parser = argparse.ArgumentParser(
        prog="texsense",
        description=(
            "texsense: textile and soft pressure sensors, from raw capacitance to accurate "
            "pressure maps. Run 'texsense COMMAND --help' for the options of a command."
        ),
    )
    parser.add_argument("--version", action="version", version=f"texsense {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    wanted = {COMMANDS[c][0] for c in commands}
    registered: set[str] = set()
    for name, (module, text) in COMMANDS.items():
        if module not in wanted:
            sub.add_parser(name, help=text, add_help=False)  # listed, options not loaded
        elif module not in registered:
            importlib.import_module(f"texsense.commands.{module}").register(sub)
            registered.add(module)
    if wanted:
        check_numbers(parser)  # every numeric option refuses what lies outside its range
        check_words(parser)  # and every path or text an empty word (ignored otherwise)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    from_command_line = argv is None
    argv = list(sys.argv[1:] if argv is None else argv)
    # matplotlib's own housekeeping (a font cache it cannot save, e.g. on a full disk) is
    # not the user's concern: the command's one line says what went wrong
    logging.getLogger("matplotlib").setLevel(logging.ERROR)
    command = _command_of(argv)
    parser = build_parser(() if command is None else (command,))
    args = parser.parse_args(argv)
    args.argv = argv  # the command line as given (a station's workers run it again)
    with _terminate_as_interrupt(), quiet_arithmetic():
        code = _run(args, lambda: check_given(parser, args, argv))
    if from_command_line:
        _leave_busy_workers(code)
    return code


#: numpy's words for arithmetic on what a file holds (no valid reading in a frame, a number
#: beyond a type): what they mean is said by the readers (invalid readings, counted)
_ARITHMETIC = (
    r"(Mean of empty slice|All-NaN (slice|axis) encountered|Degrees of freedom <= 0"
    r"|(invalid value|divide by zero) encountered|overflow encountered in cast)"
)


@contextlib.contextmanager
def quiet_arithmetic() -> Iterator[None]:
    """numpy's ``RuntimeWarning`` of arithmetic on odd data off the command's stderr, whose
    one line is the command's own: a recording whose readings are all invalid, NaN cells of a
    layout in float16 printed two lines of numpy's source around the result (harden12)."""
    with warnings.catch_warnings():  # (numpy's errors of arithmetic are warnings by default)
        warnings.filterwarnings("ignore", _ARITHMETIC, RuntimeWarning)
        yield


def _leave_busy_workers(code: int) -> None:
    """A server stopped while its workers still read (a recording that takes long to read,
    a file that does not answer): they are daemon threads nobody waits for, but the
    interpreter's teardown would share the processor with them for seconds. Once the command
    has cleaned up, end the process at once instead (only then, and only when ``main`` runs
    as the program: called with arguments by a program, it returns)."""
    busy = [t for t in threading.enumerate() if t.daemon and t.name.startswith("texsense-")]
    if busy and threading.current_thread() is threading.main_thread():
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def _run(args: argparse.Namespace, check: Callable[[], None] = lambda: None) -> int:
    """Run a parsed command after ``check`` (an option given where it has no effect:
    :mod:`texsense.commands._applies`): every failure is one line on stderr and exit 1 (one
    clean way out: a bad file or option, an output place that cannot be written, a database
    that cannot be opened, the memory budget); SIGTERM and Ctrl-C clean up as they stop."""
    try:
        check()
        return int(args.run(args) or 0)
    except (FormatError, ParameterError, UnitError, WriteError) as e:
        _say(args, f"error: {e}")
        return 1
    except Terminated:
        _say(args, "stopped (SIGTERM)")
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        _say(args, "interrupted")
        return 1
    except BrokenPipeError:  # the reader went away (`texsense ... | head`): not an error
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except OSError as e:  # an output place: no permission, a folder or a file in the way
        _say(args, f"error: {_os_error(e)}")
        return 1
    except MemoryError:
        _say(args, "error: out of memory; set the memory budget $TEXSENSE_MAX_MEMORY below "
             "what the machine has (docs/reliability.md)")  # fmt: skip
        return 1
    except Exception as e:
        if type(e).__module__.split(".")[0] not in ("sqlite3", "psycopg"):
            raise
        _say(args, f"error: the event store: {e}")
        return 1


def _say(args: argparse.Namespace, text: str) -> None:
    """The command's one line on stderr. What the user named (a file name, a value) is
    shown with its control characters escaped: a newline or a record separator in a name
    would break the line in two (``W\\x1e3: the folder W does not exist``)."""
    shown = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    print(f"texsense {args.command}: {shown}", file=sys.stderr)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is, so that its clean-up runs as for Ctrl-C."""


#: the module whose frames are h5py's callbacks into a Python file object: a stop raised there
#: is lost (h5py reports it as unraisable) and can leave HDF5 half-written (a crash at exit)
_CALLBACK_MODULES = frozenset({"texsense.io._guarded"})


_deferred: set[int] = set()  # signals to be delivered again (a timer is on its way)


def _later(sig: int) -> None:
    """Deliver ``sig`` again in a few milliseconds (from a helper thread; the main thread's
    handler runs at its next Python line); once, however often it is asked meanwhile."""
    if sig in _deferred:
        return
    _deferred.add(sig)

    def again() -> None:
        _deferred.discard(sig)
        signal.raise_signal(sig)

    timer = threading.Timer(0.005, again)
    timer.daemon = True
    timer.start()


def _in_callback(frame: FrameType | None) -> bool:
    """Whether the main thread is inside a callback whose exceptions cannot propagate (a
    frame of :data:`_CALLBACK_MODULES` anywhere on its stack)."""
    while frame is not None:
        if frame.f_globals.get("__name__") in _CALLBACK_MODULES:
            return True
        frame = frame.f_back
    return False


@contextlib.contextmanager
def _terminate_as_interrupt() -> Iterator[None]:
    """SIGTERM raises :class:`Terminated` and SIGINT ``KeyboardInterrupt`` where the program
    is, except inside h5py's callbacks into a file object, where a stop is delivered again
    a moment later (raised there it would be lost, or crash HDF5)."""

    def stop(sig: int, frame: FrameType | None) -> None:
        if _in_callback(frame):
            _later(sig)
            return
        raise Terminated if sig == signal.SIGTERM else KeyboardInterrupt

    def lost(unraisable: Any) -> None:
        """A stop raised where Python cannot raise (a weakref callback during garbage
        collection: "Exception ignored in ..."): deliver the signal again, so that it is raised
        at a later line of the program instead of being lost."""
        exc = unraisable.exc_value
        if isinstance(exc, KeyboardInterrupt):
            _later(signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT)
            return
        hook(unraisable)

    try:  # (a SIGINT that the shell set to be ignored, as for `texsense ... &`, stays so)
        previous = {
            sig: signal.signal(sig, stop)
            for sig in (signal.SIGTERM, signal.SIGINT)
            if signal.getsignal(sig) is not signal.SIG_IGN
        }
    except ValueError:  # not the main thread (texsense.cli.main called by a program)
        yield
        return
    hook, sys.unraisablehook = sys.unraisablehook, lost
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        sys.unraisablehook = hook


def _os_error(e: OSError) -> str:
    """One line for an OSError: the path(s) and the reason."""
    reason = e.strerror or str(e) or type(e).__name__
    paths = [str(p) for p in (e.filename, e.filename2) if p is not None]
    return f"{' -> '.join(paths)}: {reason}" if paths else reason


if __name__ == "__main__":
    sys.exit(main())
