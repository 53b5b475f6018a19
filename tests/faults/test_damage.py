"""Family "a damaged HDF5 file": bytes flipped anywhere in a recording are one line naming the
file (or, where the damage misses what is read, a normal answer), never a traceback. h5py
says a damaged B-tree with a ``RuntimeError`` ("wrong B-tree signature"), which the reader
caught nowhere but in its policy checks: ``texsense.io.policy.DAMAGED`` is now caught at every
read of a file's content (header, storage held, frames, timeline, frames read on demand).
"""

from __future__ import annotations

from faults._families import batch, one_line, small_recording
from texsense.io import save

#: every STEP-th byte of the file is the start of a damaged copy
STEP = 208  # (8112, a dataspace message: a RuntimeError before, is among them)


def test_bytes_flipped_anywhere_in_a_recording_are_one_line(tmp_path, fault_row):
    good = tmp_path / "good.h5"
    save(small_recording(40), good)
    data = good.read_bytes()
    argvs, names = [], []
    for k, at in enumerate(range(0, len(data) - 4, STEP)):
        blob = bytearray(data)
        for i in range(at, at + 4):
            blob[i] ^= 0xFF
        path = tmp_path / f"flip{k:04d}-at{at}.h5"
        path.write_bytes(bytes(blob))
        names.append(path.name)
        argvs.append(["info", "--json", str(path)])
        if k % 4 == 0:  # reading every frame: convert, with and without --accept-truncated
            argvs.append(["convert", str(path), str(tmp_path / f"out{k}.csv")])
            names.append(path.name)
            argvs.append(["convert", str(path), str(tmp_path / f"cut{k}.csv"),
                          "--accept-truncated"])  # fmt: skip
            names.append(path.name)
    results, _, _ = batch(argvs, tmp_path)
    refused = 0
    for name, argv, (rc, _out, err) in zip(names, argvs, results, strict=True):
        assert "Traceback" not in err, (argv, err[-1500:])
        if rc != 0:
            one_line(rc, err, name)
            refused += 1
    fault_row("damaged HDF5", f"4 bytes flipped at every {STEP}th byte of a recording "
              f"({len(argvs)} runs of info and convert)", "clear error",
              f"{refused} refused in one line, the rest read", cases=len(argvs))  # fmt: skip


def test_a_string_s_length_flipped_is_said_before_it_is_read(tmp_path):
    """A flipped byte in the stored length of a variable-length string (of the layout's
    names: contiguous; of a label: a chunk) declares gigabytes, which HDF5 allocated and
    cleared before it found that the heap's string does not match (4 GiB and ~3 s for this
    60 KB file): the reader checks the declared lengths first (texsense.io.policy.
    check_strings) and says the file is damaged, naming the string's dataset."""
    import h5py

    from faults._families import call_main

    good = tmp_path / "good.h5"
    save(small_recording(40), good)
    with h5py.File(good) as f:
        names = f["layout/names"].id.get_offset()
        label = f["labels/posture"].id.get_chunk_info(0).byte_offset
    for what, at in (("/layout/names", names + 16 * 3), ("/labels/posture", label + 16 * 5)):
        blob = bytearray(good.read_bytes())
        assert blob[at : at + 4] in (b"\x02\0\0\0", b"\x03\0\0\0")  # "s3", "sit": its length
        blob[at : at + 4] = b"\xfd\xff\xff\xff"
        path = tmp_path / f"flipped-{what.rsplit('/', 1)[1]}.h5"
        path.write_bytes(bytes(blob))
        for argv in (["info", str(path)], ["convert", str(path), str(tmp_path / "out.csv")]):
            rc, _out, err = call_main(argv)
            line = one_line(rc, err, path.name)
            assert f"a string of {what} declares 4294967293 bytes" in line, line
