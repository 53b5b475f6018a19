"""Family "a file that reaches outside itself" (issue 32, item 1): every way an HDF5 file can
make its reader read something else (external storage, an external link, a soft link, a
virtual dataset, a filter outside the list, a committed datatype, and the dtypes texsense does
not read: complex, compound, references, variable-length arrays), put in every place of the
recording schema, through every place texsense opens an HDF5 file: ``texsense info``,
``convert`` and ``report`` (one child process), the Python API (``load``, ``open_reader``),
the archive's check of an earlier output and the monitor's playback routes.

Each case must be refused in one line naming the file and the dataset (or link), nothing may
be written, and the bytes of the file outside (a "secret" text) never appear anywhere.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from fastapi.testclient import TestClient

from faults._families import batch, one_line, small_recording
from texsense.exceptions import FormatError
from texsense.io import load, open_reader, save

SECRET = b"TOP-SECRET-0123456789-abcdefghij-" * 8

#: where in the schema a construct is put (a dataset the reader reads, or one it does not)
PLACES = ["/frames", "/times", "/valid", "/labels/posture", "/layout/xy_cm", "/layout/names",
          "/layout/regions/r", "/layout/cells", "/unused"]  # fmt: skip


def _external_storage(f, name, shape, outside):
    f.create_dataset(name, shape, np.float32, external=[(str(outside / "secret.txt"), 0, 4096)])


def _external_link(f, name, shape, outside):
    f[name] = h5py.ExternalLink(str(outside / "other.h5"), "/x")


def _soft_link(f, name, shape, outside):
    f[name] = h5py.SoftLink("/times" if name != "/times" else "/frames")


def _virtual(f, name, shape, outside):
    layout = h5py.VirtualLayout(shape=(5, 12), dtype=np.float32)
    layout[:] = h5py.VirtualSource(str(outside / "other.h5"), "x", shape=(5, 12))
    f.create_virtual_dataset(name, layout)


def _unlisted_filter(f, name, shape, outside):
    f.create_dataset(name, data=np.ones(shape), scaleoffset=2)


def _committed_type(f, name, shape, outside):
    f[name] = np.dtype("f4")


def _dtype(dtype):
    def make(f, name, shape, outside):
        f.create_dataset(name, shape, dtype)

    return make


CONSTRUCTS = {
    "external storage": (_external_storage, "stored in another file"),
    "external link": (_external_link, "external link"),
    "soft link": (_soft_link, "soft link"),
    "virtual dataset": (_virtual, "virtual"),
    "filter outside the list": (_unlisted_filter, "uses filter"),
    "committed datatype": (_committed_type, "Datatype"),
    "complex numbers": (_dtype(np.complex64), "complex"),
    "compound type": (_dtype([("a", "f4"), ("b", "i4")]), "compound"),
    "object references": (_dtype(h5py.ref_dtype), "references"),
    "variable-length arrays": (_dtype(h5py.vlen_dtype(np.float32)), "variable-length"),
}
CASES = [(c, p) for c in CONSTRUCTS for p in PLACES]


def _spoil(base: Path, target: Path, construct: str, place: str, outside: Path) -> Path:
    shutil.copy(base, target)
    with h5py.File(target, "a") as f:
        shape = f[place].shape if place in f else (5, 12)
        if place in f:
            del f[place]
        CONSTRUCTS[construct][0](f, place, shape, outside)
    return target


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """{(construct, place): path} in a folder of their own; the secret and the other HDF5 file
    in a folder beside it (outside)."""
    root = tmp_path_factory.mktemp("reach")
    outside, folder = root / "outside", root / "recordings"
    outside.mkdir()
    folder.mkdir()
    (outside / "secret.txt").write_bytes(SECRET * 16)
    with h5py.File(outside / "other.h5", "w") as g:
        g["x"] = np.frombuffer(SECRET[:240], np.float32).reshape(5, 12)
    base = save(small_recording(), root / "base.h5")
    return {
        (c, p): _spoil(base, folder / f"{k:02d}.h5", c, p, outside)
        for k, (c, p) in enumerate(CASES)
    }


def _name_of(place: str, construct: str) -> str:
    return place


@pytest.fixture(scope="module")
def cli(files):
    """Every case through ``info``, ``convert`` (to CSV) and ``report`` in one child."""
    folder = next(iter(files.values())).parent
    argvs = []
    for path in files.values():
        argvs += [["info", str(path)], ["convert", str(path), str(path.with_suffix(".csv"))],
                  ["report", str(path), "-o", str(path.with_suffix(".html"))]]  # fmt: skip
    results, _, _ = batch(argvs, folder)
    return {key: results[3 * k : 3 * k + 3] for k, key in enumerate(files)}


@pytest.mark.parametrize(("construct", "place"), CASES, ids=[f"{c} at {p}" for c, p in CASES])
def test_a_file_cannot_reach_outside_itself(files, cli, construct, place, fault_row):
    path = files[construct, place]
    said = CONSTRUCTS[construct][1]
    for rc, out, err in cli[construct, place]:  # info, convert, report
        line = one_line(rc, err, path.name, place, said)
        assert SECRET[:16].decode() not in out + line
    assert not path.with_suffix(".csv").exists() and not path.with_suffix(".html").exists()
    with pytest.raises(FormatError, match=said):
        load(path)
    with pytest.raises(FormatError, match=said):
        open_reader(path)
    fault_row(
        "reach outside",
        f"{construct} at {place}",
        "clear error",
        "info, convert, report, load, open_reader",
        cases=5,
    )


def test_every_hdf5_entry_point_uses_the_policy(files, tmp_path, fault_row):
    """The archive's check of an earlier output and the monitor's playback: each case is not
    an output of ours / a 422 naming the file, and never a 200."""
    from texsense.compensation.archive import _output_matches
    from texsense.monitor.live import Monitor
    from texsense.monitor.server import create_app
    from texsense.monitor.sources import ReplaySource

    folder = next(iter(files.values())).parent
    assert not any(_output_matches(p, "id", "digest") for p in files.values())
    monitor = Monitor(ReplaySource(small_recording(), speed=0), record_dir=folder)
    client = TestClient(create_app(monitor, run_source=False), base_url="http://127.0.0.1:8765")
    for (construct, place), path in files.items():
        for route in (f"/api/playback/{path.name}", f"/api/playback/{path.name}/frames/0"):
            r = client.get(route)
            assert r.status_code == 422, (construct, place, route, r.status_code)
            detail = r.json()["detail"]
            assert path.name in detail and place in detail, detail
            assert SECRET[:16].decode() not in r.text
    fault_row(
        "reach outside",
        f"the {len(files)} files in the monitor's playback "
        "(summary, a frame) and the archive's output check",
        "refused",
        cases=2 * len(files) + 1,
    )


def test_the_bounds_are_read_under_the_policy_too(files, fault_row):
    """``read_bounds`` (the report's and the playback's bounds of a processed recording)
    opens its file as every reader does: each construct refused in one line naming the file."""
    from texsense.io.hdf5 import read_bounds

    for (construct, place), path in files.items():
        with pytest.raises(FormatError, match=CONSTRUCTS[construct][1]) as got:
            read_bounds(path)
        said = str(got.value)
        assert path.name in said and place in said and SECRET[:16].decode() not in said
    fault_row("reach outside", f"the {len(files)} files through read_bounds", "refused",
              cases=len(files))  # fmt: skip
