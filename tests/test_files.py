"""texsense.data.files: writes that never lose the previous file."""

import os
import stat

import pytest

from texsense.data.files import atomic_path, check_not_input, unused_name, write_bytes, write_text
from texsense.exceptions import ParameterError, WriteError


def test_new_file_gets_the_umask_permissions_not_private(tmp_path):
    old = os.umask(0o022)
    try:
        path = write_text(tmp_path / "report.txt", "x")
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644


def test_replaced_file_keeps_its_permissions(tmp_path):
    path = tmp_path / "model.json"
    path.write_text("old")
    path.chmod(0o640)
    write_text(path, "new")
    assert path.read_text() == "new"
    assert stat.S_IMODE(path.stat().st_mode) == 0o640


def test_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    path = write_bytes(tmp_path / "a.bin", b"old")

    def fail(_tmp):
        raise OSError(28, "No space left on device")

    with (
        pytest.raises(WriteError, match=r"No space left on device.*unchanged"),
        atomic_path(path) as tmp,
    ):
        fail(tmp)
    assert path.read_bytes() == b"old"
    assert os.listdir(tmp_path) == ["a.bin"]


def test_missing_folder_and_folder_target_are_write_errors(tmp_path):
    with pytest.raises(WriteError, match="does not exist"):
        write_text(tmp_path / "no" / "x.txt", "x")
    with pytest.raises(WriteError, match="is a folder"):
        write_text(tmp_path, "x")


def test_output_onto_input_is_refused(tmp_path):
    src = write_text(tmp_path / "raw.h5", "x")
    os.symlink(src, tmp_path / "link.h5")
    for out in (src, tmp_path / "link.h5", tmp_path / "." / "raw.h5"):
        with pytest.raises(ParameterError, match="also an input"):
            check_not_input(out, [src])
    check_not_input(tmp_path / "other.h5", [src])


def test_unused_name_counts_up(tmp_path):
    first = unused_name(tmp_path / "s.h5")
    assert first.name == "s.h5"
    write_text(first, "")
    write_text(tmp_path / "s-2.h5", "")
    assert unused_name(first).name == "s-3.h5"


def test_hdf5_letting_go_of_a_stopped_writer_says_nothing(tmp_path, monkeypatch):
    """A writer stopped mid-way (SIGTERM in `process`) closes its guarded file; HDF5 lets go
    of its own file object later and flushes through the guard: dropped, not a traceback
    ('Exception ignored ... I/O operation on closed file' ended a stopped `process`)."""
    import gc
    import sys

    import h5py

    from texsense.io._guarded import GuardedFile

    unraisable: list[BaseException | None] = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: unraisable.append(u.exc_value))
    guard = GuardedFile(tmp_path / "stopped.h5")
    f = h5py.File(guard, "w")
    f["x"] = list(range(1000))
    guard.close()
    del f
    gc.collect()
    assert unraisable == []
