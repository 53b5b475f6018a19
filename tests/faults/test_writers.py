"""Family "an output place that cannot be written", seen from the Python API (harden9 item 7):
every writer of texsense x every place the file system refuses before anything is written
(names too long for it, a folder name too long, a NUL, a loop of links, a file or a device in
the way, a missing folder). Each is a :class:`~texsense.exceptions.WriteError` naming the
place (the project's error for a write, which ``texsense.cli`` prints as one line), never a
bare ``OSError`` or ``ValueError``, and no temporary file is left. The command line's side is
``test_outputs.py``.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from faults._families import small_recording
from texsense.compensation.stages import StageChain
from texsense.data import files
from texsense.exceptions import WriteError
from texsense.io import save


def _figure_writer(path: Path) -> None:
    plt = files.pyplot()
    fig = plt.figure(figsize=(1, 1))
    try:
        files.save_figure(fig, path)
    finally:
        plt.close(fig)


def _chain(path: Path) -> None:
    import numpy as np

    from texsense.compensation.stages import Linear

    StageChain([Linear("capacitance", "pF", "pressure", "N/cm2").fit(np.zeros(6), np.ones(6))]
               ).save(path)  # fmt: skip


#: writer -> (suffix of its file, how it writes a file at a path)
WRITERS = {
    "write_text": (".txt", lambda p: files.write_text(p, "x")),
    "write_bytes": (".bin", lambda p: files.write_bytes(p, b"x")),
    "atomic_open": (".txt", lambda p: files.atomic_open(p).__enter__()),
    "save .h5": (".h5", lambda p: save(small_recording(), p)),
    "save .csv": (".csv", lambda p: save(small_recording(), p)),
    "save .asf": (".asf", lambda p: save(small_recording(), p)),
    "save_figure": (".png", _figure_writer),
    "a model file": (".json", _chain),
}


def _places(root: Path) -> dict[str, tuple[str, str]]:
    """kind -> (the path without its suffix, what the error says)."""
    (root / "afile").write_text("a file")
    (root / "afolder.txt").mkdir()
    if not (root / "loop1").is_symlink():
        os.symlink("loop2", root / "loop1")
        os.symlink("loop1", root / "loop2")
        for suffix in {s for s, _ in WRITERS.values()}:
            os.symlink("/dev/full", root / f"dev{suffix}")
    return {
        "a name too long": (str(root / ("n" * 300)), "too long"),
        "a folder name too long": (str(root / ("d" * 300) / "x"), "too long"),
        "a path too long": (str(root / "/".join(["p" * 250] * 20) / "x"), "too long"),
        "a NUL in the name": (str(root / "a\x00b"), "NUL"),
        "a NUL in the folder": (str(root / "a\x00b" / "x"), "NUL"),
        "a file where a folder is": (str(root / "afile" / "x"), "is a file"),
        "a loop of links as folder": (str(root / "loop1" / "x"), "loop"),
        "a missing folder": (str(root / "missing" / "x"), "does not exist"),
        "a device": (str(root / "dev"), "not a regular file"),
    }


def test_every_writer_refuses_every_bad_place_with_a_write_error(tmp_path, fault_row):
    places = _places(tmp_path)
    wrong, tried = [], 0
    for kind, (stem, said) in places.items():
        for name, (suffix, write) in WRITERS.items():
            path = stem + suffix
            tried += 1
            try:
                write(Path(path))
            except WriteError as e:
                if said not in str(e):
                    wrong.append(f"{kind} / {name}: {said!r} not in {str(e)[:200]}")
                continue
            except BaseException as e:  # what else escapes is the failure
                wrong.append(f"{kind} / {name}: {type(e).__name__}: {str(e)[:160]}")
                continue
            wrong.append(f"{kind} / {name}: written")
    leftovers = [str(p) for p in tmp_path.rglob(".texsense-tmp-*")]
    assert wrong == [], f"{len(wrong)} of {tried}:\n" + "\n".join(wrong)
    assert leftovers == []
    fault_row("output place", f"{len(WRITERS)} writers of the API x {len(places)} places the "
              "file system refuses", "clear error", "WriteError naming the place",
              cases=tried)  # fmt: skip


@pytest.mark.parametrize("kind", ["a name too long", "a folder name too long"])
def test_the_command_line_says_it_in_one_line(tmp_path, kind):
    from faults._families import one_line
    from texsense.cli import main

    src = save(small_recording(), tmp_path / "rec.h5")
    stem = _places(tmp_path)[kind][0]
    for suffix in (".h5", ".csv", ".png"):
        import contextlib
        import io

        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            argv = ["convert", str(src), stem + suffix]
            if suffix == ".png":
                argv = ["plot", str(src), "-o", stem + suffix]
            rc = main(argv)
        one_line(rc, err.getvalue(), "too long")
