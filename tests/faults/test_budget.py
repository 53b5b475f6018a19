"""Family "a file that declares more than it holds" (issue 32, item 2): headers, shapes,
chunks and grid sizes far beyond what the file holds or the machine has, in every format and
every place a declared number turns into an allocation. Each runs under a memory budget of
64 MiB (``TEXSENSE_MAX_MEMORY``) through ``texsense info`` and ``convert`` in one child
process, whose peak memory may exceed its warm-up peak by the budget plus a constant at most;
each is a clear one-line refusal or read right. Then the layouts built from numbers (a ward
file's ``grid:100000x100000``, ``monitor --grid``, the Python API) and the monitor's
playback of such a file.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from faults._families import batch, one_line, small_recording
from texsense import Layout
from texsense.exceptions import FormatError, ParameterError
from texsense.io import save

BUDGET = "64M"
BUDGET_KIB = 64 * 1024
#: what a child may take beyond its warm-up peak besides the budget (numpy's, h5py's and
#: matplotlib's own first allocations), KiB
CONSTANT_KIB = 96 * 1024


def _h5(base: Path, folder: Path, name: str, edit) -> Path:
    path = folder / name
    shutil.copy(base, path)
    with h5py.File(path, "a") as f:
        edit(f)
    return path


def _bomb(frames: int):
    """Every per-frame dataset declares ``frames`` frames, all stored, compressed to nothing."""

    def edit(f):
        n = f["frames"].shape[1]
        for key, dtype, per in (("frames", np.float32, (n,)), ("valid", bool, (n,)),
                                ("times", np.float64, ())):  # fmt: skip
            del f[key]
            ds = f.create_dataset(key, (frames, *per), dtype, chunks=(4096, *per),
                                  compression="gzip", fillvalue=0)  # fmt: skip
            block = np.ones((1 << 18, *per), dtype)  # (h5py writes a scalar row by row)
            for a in range(0, frames, 1 << 18):
                b = min(frames, a + (1 << 18))
                ds[a:b] = np.arange(a, b, dtype=np.float64) if key == "times" else block[: b - a]
        del f["labels/posture"]

    return edit


def _layout_bomb(key: str, rows: int):
    def edit(f):
        old = f[f"layout/{key}"]
        shape, dtype = (rows, *old.shape[1:]), old.dtype
        del f[f"layout/{key}"]
        f.create_dataset(f"layout/{key}", shape, dtype, chunks=(min(rows, 1 << 16), *shape[1:]),
                         compression="gzip")  # fmt: skip

    return edit


def _huge_chunk(f):
    del f["labels/posture"]
    data = f["frames"][()]
    del f["frames"]
    f.create_dataset("frames", data=data, chunks=None, maxshape=(None, 12))  # a placeholder
    del f["frames"]
    f.create_dataset("frames", (5, 12), np.float32, maxshape=(None, 12), chunks=(1 << 24, 12),
                     compression="gzip")  # fmt: skip


def _sparse_grid(f):
    f["layout"].attrs["rows"], f["layout"].attrs["cols"] = 100_000, 100_000


def _tekscan(rows: int, cols: int, frames: int = 1, end: int | None = None) -> str:
    last = frames if end is None else end
    head = ["DATA_TYPE MOVIE", f"ROWS {rows}", f"COLS {cols}", "ROW_SPACING 1 centimeters",
            "COL_SPACING 1 centimeters", "SECONDS_PER_FRAME 0.1", "START_FRAME 1",
            f"END_FRAME {last}", "UNITS raw", "ASCII_DATA @@", ""]  # fmt: skip
    grid = (",".join(["1"] * cols) + "\n") * rows
    body = "".join(f"Frame {k + 1}, {k * 0.1}\n" + grid + "\n" for k in range(frames))
    return "\n".join(head) + "\n" + body + "@@\n"


def _wide(elements: int, frames: int, declared: int | None = None, layout: str = "") -> str:
    head = ["# texsense wide-csv 2", "# quantity: raw", "# unit: count",
            f"# frames: {frames if declared is None else declared}"]  # fmt: skip
    if layout:
        head.append(f"# layout: {layout}")
    head.append("time_s," + ",".join(f"e{k}" for k in range(elements)) + ",invalid")
    row = ",".join(["1"] * elements)
    return "\n".join(head) + "\n" + "".join(f"{k},{row},\n" for k in range(frames))


#: (name, how to make it, what the refusal says; None: read right)
def _cases(base: Path, folder: Path) -> list[tuple[str, Path, str | None]]:
    text = {
        "tekscan-3000x3000.asf": _tekscan(3000, 3000),
        "tekscan-end-frame-1e9.asf": _tekscan(4, 4, 2, end=10**9),
        "wide-1e9-frames.csv": _wide(4, 3, declared=10**9),
        "wide-sparse-layout.csv": _wide(2, 2, layout='{"xy_cm":[[0,0],[1,0]],"size_cm":[1,1],'
                                        '"shape":[100000,100000],"cells":[0,1],'
                                        '"neighbours_indptr":[0,0,0],"neighbours_indices":[]}'),
        "wide-longer-than-the-budget.csv": _wide(200, 18_000),
    }  # fmt: skip
    for name, body in text.items():
        (folder / name).write_text(body)
    return [
        ("HDF5: 250,000 frames of one compressed chunk", _h5(base, folder, "bomb.h5",
         _bomb(250_000)), "reading 250000 frames"),
        ("HDF5: a layout of 10^8 element centres", _h5(base, folder, "xy.h5",
         _layout_bomb("xy_cm", 10**8)), "/layout"),
        ("HDF5: 10^8 neighbour indices", _h5(base, folder, "nb.h5",
         _layout_bomb("neighbours_indices", 10**8)), "/layout"),
        ("HDF5: 10^8 element names", _h5(base, folder, "names.h5",
         _layout_bomb("names", 10**8)), "/layout"),
        ("HDF5: one chunk of 16 M frames", _h5(base, folder, "chunk.h5", _huge_chunk),
         "one chunk of the dataset /frames"),
        ("HDF5: a grid of 100000 x 100000 cells for 12 elements", _h5(base, folder,
         "sparse.h5", _sparse_grid), "100000 x 100000"),
        ("Tekscan: ROWS 3000 COLS 3000", folder / "tekscan-3000x3000.asf", "3000 x 3000"),
        ("Tekscan: END_FRAME 10^9", folder / "tekscan-end-frame-1e9.asf", "END_FRAME"),
        ("wide CSV: '# frames: 10^9' (3 held)", folder / "wide-1e9-frames.csv", "10⁹|1000000000"),
        ("wide CSV: a layout of 100000 x 100000 cells for 2", folder / "wide-sparse-layout.csv",
         "100000 x 100000"),
        ("wide CSV: more frames than the budget holds", folder / "wide-longer-than-the-budget.csv",
         "memory budget"),
    ]  # fmt: skip


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    folder = tmp_path_factory.mktemp("budget")
    base = save(small_recording(), folder / "base.h5")
    cases = _cases(base, folder)
    argvs = []
    for _, path, _ in cases:
        argvs += [["info", str(path)], ["convert", str(path), str(path) + ".out.h5"]]
    warm = [["info", str(base)], ["convert", str(base), str(folder / "warm.h5")]]
    env = {"TEXSENSE_MAX_MEMORY": BUDGET}
    results, base_kib, peak_kib = batch(argvs, folder, warm=warm, env=env)
    return cases, results, base_kib, peak_kib


def test_declared_sizes_are_refused_within_the_budget(outcomes, fault_row):
    cases, results, base_kib, peak_kib = outcomes
    for k, (case, path, said) in enumerate(cases):
        for rc, _out, err in results[2 * k : 2 * k + 2]:
            line = one_line(rc, err, path.name)
            assert any(s in line for s in said.split("|")), (case, line)
        assert not Path(str(path) + ".out.h5").exists()
        fault_row(
            "declares more", case, "clear error", "info, convert under a 64 MiB budget", cases=2
        )
    grown = peak_kib - base_kib
    assert grown <= BUDGET_KIB + CONSTANT_KIB, f"the child grew by {grown} KiB"
    fault_row(
        "declares more",
        f"peak memory of those {len(results)} commands",
        "within the budget",
        f"{grown // 1024} MiB over the warm-up, budget 64 MiB",
    )


@pytest.mark.parametrize("build", [
    lambda: Layout.grid(100_000, 100_000),
    lambda: Layout(np.zeros((2, 2)), (1, 1), shape=(100_000, 100_000), cells=[0, 1]),
    lambda: Layout.grid(50_000, 50_000, active=None),
], ids=["grid 100000 x 100000", "2 elements on 10^10 cells", "grid 50000 x 50000"])  # fmt: skip
def test_layouts_from_numbers_are_checked_before_allocation(build, monkeypatch, fault_row):
    monkeypatch.setenv("TEXSENSE_MAX_MEMORY", BUDGET)
    with pytest.raises(ParameterError, match=r"budget|cells for"):
        build()
    fault_row("declares more", "a layout from numbers (Python API)", "clear error")


def test_a_ward_line_or_an_option_cannot_allocate_a_grid(tmp_path, fault_row):
    (tmp_path / "ward.toml").write_text('[[mat]]\nid = "a"\nlayout = "grid:100000x100000"\n')
    argvs = [["station", "--config", "ward.toml", "--port", "1"],
             ["monitor", "--source", "mqtt:127.0.0.1:1", "--grid", "100000x100000", "--port", "1"],
             ["record", "--source", "mqtt:127.0.0.1:1", "--grid", "100000x100000",
              "-o", "x.h5", "--frames", "1"]]  # fmt: skip
    results, base_kib, peak_kib = batch(argvs, tmp_path, env={"TEXSENSE_MAX_MEMORY": BUDGET})
    for argv, (rc, _out, err) in zip(argvs, results, strict=True):
        one_line(rc, err, "100000 x 100000")
        fault_row("declares more", f"texsense {argv[0]} with a grid of 100000 x 100000",
                  "clear error", cases=1)  # fmt: skip
    assert peak_kib - base_kib <= BUDGET_KIB + CONSTANT_KIB


def test_playback_of_a_file_beyond_the_budget_is_refused(outcomes, monkeypatch, fault_row):
    """Every file of the family but the HDF5 chunk bomb is refused by the playback as by
    the commands; the bomb's 250,000 frames of 12 elements are all there (one repeated
    chunk), so the playback, which reads HDF5 on demand, would play them: that a recording
    longer than the budget plays is test_playback_demand.py's (the 250,000 frames would take
    tens of seconds of the alert engine here)."""
    from fastapi.testclient import TestClient

    from texsense.monitor.live import Monitor
    from texsense.monitor.server import create_app
    from texsense.monitor.sources import ReplaySource

    monkeypatch.setenv("TEXSENSE_MAX_MEMORY", BUDGET)
    cases = outcomes[0]
    folder = cases[0][1].parent
    monitor = Monitor(ReplaySource(small_recording(), speed=0), record_dir=folder)
    with TestClient(create_app(monitor, run_source=False), base_url="http://127.0.0.1:8765") as c:
        refused = [(case, path) for case, path, _ in cases if path.name != "bomb.h5"]
        for case, path in refused:
            r = c.get(f"/api/playback/{path.name}")
            assert r.status_code == 422 and path.name in r.json()["detail"], (case, r.text)
        fault_row("declares more", f"the {len(refused)} files in the monitor's playback",
                  "refused", cases=len(refused))  # fmt: skip
    with pytest.raises(FormatError, match="memory budget"):
        from texsense.io import load

        load(cases[0][1])
