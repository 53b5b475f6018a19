"""Reading a whole recording in a child process, for a server.

A text recording (CSV, a Tekscan or XSENSOR export, a PMD tree) is parsed line by line in
Python: seconds of work for a large file, during which a thread that parses it holds Python's
lock most of the time. In a server, every other thread then waits its turn for each step it
takes, and a request that is answered in 10 ms when the server is idle took 4-5 s while one
such file was read for playback (``tests/faults/test_entries.py``). So a server reads such a
file in a child process of its own (:func:`load_apart`): the parsing holds the child's lock,
never the server's, and the server only waits (without its lock) for the result.

The child is started for the one file (``spawn``: no copy of the server's threads or
sockets), reads it with :func:`texsense.io.load` within the memory budget the caller has
(:func:`texsense.data.budget.share`), and sends the recording back through a pipe (the
frames are pickled once). A reader's refusal comes back as the same exception with the same
one-line message. A server that is told to stop (:data:`texsense._progress.STOPPING`) ends
the child at once instead of waiting for it.
"""

from __future__ import annotations

import multiprocessing
import pickle
from pathlib import Path
from typing import Any

from texsense._progress import STOPPING, StoppingError
from texsense.data import budget
from texsense.data.recording import Recording
from texsense.exceptions import FormatError, ParameterError, UnitError

__all__ = ["load_apart"]

#: The refusals a reader raises, sent back as themselves (anything else as a FormatError).
_KNOWN: dict[str, type[Exception]] = {
    e.__name__: e for e in (FormatError, ParameterError, UnitError, OSError, MemoryError)
}
_POLL_S = 0.1


def _child(conn: Any, path: str, memory: int) -> None:
    """In the child: read ``path`` within ``memory`` bytes; send ``("ok", recording)`` or
    ``("error", class name, message, its plain attributes)``."""
    from texsense.io import load

    try:
        with budget.share(memory):
            rec = load(path)
        conn.send_bytes(pickle.dumps(("ok", rec), protocol=pickle.HIGHEST_PROTOCOL))
    except Exception as e:  # sent to the parent, which raises it as its own
        facts = {k: v for k, v in vars(e).items() if isinstance(v, str | int | Path | None)}
        conn.send_bytes(pickle.dumps(("error", type(e).__name__, str(e), facts)))
    finally:
        conn.close()


def load_apart(path: str | Path, memory: int | None = None) -> Recording:
    """:func:`texsense.io.load` of ``path``, done in a child process (see the module).

    Parameters
    ----------
    path : str or Path
        A recording texsense reads (any format; an HDF5 recording is better opened on demand,
        :func:`texsense.io.open_recording`).
    memory : int, optional
        The memory budget of the read, bytes (default: this thread's budget).

    Raises
    ------
    FormatError, ParameterError, UnitError, OSError, MemoryError
        The reader's refusal, with its message (another error in the child: a FormatError
        naming it).
    StoppingError
        If the server is told to stop while the child reads (the child is ended).
    """
    memory = budget.max_memory() if memory is None else int(memory)
    context = multiprocessing.get_context("spawn")
    receive, send = context.Pipe(duplex=False)
    child = context.Process(
        target=_child, args=(send, str(path), memory), name="texsense-read", daemon=True
    )
    child.start()
    send.close()  # the child holds the sending end: a child that dies closes the pipe
    try:
        while not receive.poll(_POLL_S):
            if STOPPING.is_set():
                raise StoppingError("the server stops")
            if not child.is_alive() and not receive.poll(0):
                raise FormatError(path, f"the reader ended without an answer ({child.exitcode})")
        try:
            answer = pickle.loads(receive.recv_bytes())
        except EOFError:
            raise FormatError(path, "the reader ended without an answer") from None
    finally:
        receive.close()
        if child.is_alive():
            child.terminate()
        child.join(timeout=5)
    if answer[0] == "ok":
        return answer[1]
    kind = _KNOWN.get(answer[1])
    if kind is None:
        raise FormatError(path, f"{answer[1]}: {answer[2]}")
    error = kind.__new__(kind)  # as raised in the child: its message, path, line, detail
    error.args = (answer[2],)
    vars(error).update(answer[3])
    raise error
