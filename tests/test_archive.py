"""texsense process on one file (in blocks, atomic, restartable) and on archives (one task per
file on a real Dask LocalCluster started by the test)."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from texsense.calibration.workflows import seat_calibration
from texsense.cli import main
from texsense.compensation.archive import (
    ProcessOptions,
    archive_jobs,
    process_archive,
    process_file,
)
from texsense.compensation.pipeline import NEAR_ZERO_NCM2, Pipeline
from texsense.compensation.stages import Linear, StageChain
from texsense.io import load, save
from texsense.sim.seated import Subject, simulate_session

PMD = "pmd/experiment-i"


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    """Three short capacitance sessions of the virtual seat and the seat's calibration."""
    root = tmp_path_factory.mktemp("raw")
    cal = seat_calibration(mat_seed=5)
    cal.save(root / "calibration.json")
    (root / "sessions").mkdir()
    for k in range(3):
        s = simulate_session(Subject.random(k), rounds=1, rest_s=20.0, posture_s=10.0)
        save(s.capacitance, root / "sessions" / f"s{k}.h5")
    return root, cal


def test_one_file_in_blocks_equals_the_whole_recording(sessions, tmp_path):
    root, cal = sessions
    src = root / "sessions" / "s0.h5"
    rec = load(src)
    # in blocks as a whole, the in-use drift correction (on by default in process) included
    expected = Pipeline(cal, rec.layout, repair="neighbour-mean", in_use=True).run(rec)
    report = process_file(
        src, cal, tmp_path / "p.h5", ProcessOptions(repair="neighbour-mean", chunk_frames=37)
    )
    assert report.status == "done" and report.frames == rec.n_frames > 37
    out = load(tmp_path / "p.h5")
    # an empty element's estimate just below zero is written as 0 (pipeline.no_negative);
    # further below zero is no reading: the file marks it invalid (as every reader would),
    # the rest of the mask is the pipeline's
    near = (expected.frames < 0) & (expected.frames >= -NEAR_ZERO_NCM2)
    np.testing.assert_array_equal(out.frames, np.where(near, 0, expected.frames))
    ok = expected.frames >= -NEAR_ZERO_NCM2
    np.testing.assert_array_equal(out.valid, expected.valid & ok)
    np.testing.assert_array_equal(out.labels["posture"], rec.labels["posture"])
    assert out.meta["calibration_id"] == cal.id and len(out.meta["input_sha256"]) == 64
    assert 0 < report.failed_share < 0.5


def test_a_second_run_skips_what_is_done_and_redoes_what_changed(sessions, tmp_path):
    root, cal = sessions
    src = tmp_path / "in.h5"
    src.write_bytes((root / "sessions" / "s1.h5").read_bytes())
    dst = tmp_path / "out.h5"
    assert process_file(src, cal, dst).status == "done"
    stamp = dst.stat().st_mtime_ns
    assert process_file(src, cal, dst).status == "skipped"
    assert dst.stat().st_mtime_ns == stamp
    # another calibration: redone
    other = StageChain([Linear("capacitance", "pF").fit(np.zeros(96), np.ones(96))])
    assert process_file(src, other, dst).status == "done"
    assert load(dst).meta["calibration_id"] == other.id
    # another input: redone
    rec = load(src)
    save(rec.select(slice(0, 50)), src)
    assert process_file(src, other, dst).status == "done"
    assert load(dst).n_frames == 50


def test_a_failure_leaves_neither_output_nor_partial_file(sessions, tmp_path, monkeypatch):
    root, cal = sessions
    calls = {"n": 0}
    original = Pipeline.process

    def failing(self, *a, **kw):
        calls["n"] += 1
        if calls["n"] == 2:
            raise RuntimeError("disk full (simulated)")
        return original(self, *a, **kw)

    monkeypatch.setattr(Pipeline, "process", failing)
    with pytest.raises(RuntimeError, match="disk full"):
        process_file(
            root / "sessions" / "s2.h5", cal, tmp_path / "x.h5", ProcessOptions(chunk_frames=40)
        )
    assert calls["n"] == 2 and list(tmp_path.iterdir()) == []


def test_archive_on_a_local_cluster_reports_a_bad_file_and_does_the_rest(sessions, tmp_path):
    """Scheduler and two worker processes started here; one input holds pressure instead of
    capacitance: it fails with its reason, the three sessions are processed."""
    from dask.distributed import LocalCluster

    root, cal = sessions
    bad = tmp_path / "in" / "bad.h5"
    bad.parent.mkdir()
    save(load(root / "sessions" / "s0.h5")._with(quantity="pressure", unit="N/cm2"), bad)
    (tmp_path / "in" / "notes.txt").write_text("not a recording\n")
    with pytest.raises(Exception, match="unknown format"):
        load(tmp_path / "in" / "notes.txt")
    jobs, ignored = archive_jobs([str(root / "sessions"), str(tmp_path / "in")], tmp_path / "o")
    assert [p.name for p in ignored] == ["notes.txt"] and len(jobs) == 4
    with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=":0") as cluster:
        reports = process_archive(
            jobs, root / "calibration.json", ProcessOptions(repair="idw8"),
            scheduler=cluster.scheduler_address,
        )  # fmt: skip
        assert len(cluster.scheduler.workers) == 2
    status = {Path(r.source).name: r.status for r in reports}
    assert status == {"s0.h5": "done", "s1.h5": "done", "s2.h5": "done", "bad.h5": "failed"}
    why = next(r.error for r in reports if r.status == "failed")
    assert "holds pressure" in why and "capacitance" in why
    for k in range(3):
        out = load(tmp_path / "o" / f"s{k}.h5")
        assert out.quantity == "pressure" and out.meta["calibration_id"] == cal.id
    assert not list((tmp_path / "o").glob(".*partial"))


def test_a_small_archive_is_processed_here_with_the_same_reports(sessions, tmp_path, monkeypatch):
    """No scheduler, no worker count, inputs under IN_PROCESS_BYTES: no cluster is started,
    the outputs are those of the one-file path, a bad file is a failed report and an
    unexpected error in one file does not stop the others; above the size, a cluster."""
    import dask.distributed

    from texsense.compensation import archive

    def no_cluster(*a, **kw):
        raise AssertionError("a LocalCluster was started")

    monkeypatch.setattr(dask.distributed, "LocalCluster", no_cluster)
    root, cal = sessions
    bad = tmp_path / "in" / "bad.h5"
    bad.parent.mkdir()
    save(load(root / "sessions" / "s0.h5")._with(quantity="pressure", unit="N/cm2"), bad)
    jobs, _ = archive_jobs([str(root / "sessions"), str(tmp_path / "in")], tmp_path / "o")
    original = archive.process_file

    def s1_breaks(src, *a, **kw):
        if Path(src).name == "s1.h5":
            raise RuntimeError("a bug (simulated)")
        return original(src, *a, **kw)

    monkeypatch.setattr(archive, "process_file", s1_breaks)
    reports = process_archive(jobs, root / "calibration.json", ProcessOptions(repair="idw8"))
    status = {Path(r.source).name: (r.status, r.error) for r in reports}
    assert status["s0.h5"] == status["s2.h5"] == ("done", "")
    assert status["bad.h5"][0] == "failed" and "holds pressure" in status["bad.h5"][1]
    assert status["s1.h5"] == ("failed", "RuntimeError: a bug (simulated)")
    process_file(
        root / "sessions" / "s2.h5", cal, tmp_path / "one.h5", ProcessOptions(repair="idw8")
    )
    np.testing.assert_array_equal(
        load(tmp_path / "o" / "s2.h5").frames, load(tmp_path / "one.h5").frames
    )
    # the same jobs above the size go to a cluster (the patched one says so)
    monkeypatch.setattr(archive, "IN_PROCESS_BYTES", 1)
    with pytest.raises(AssertionError, match="LocalCluster was started"):
        process_archive(jobs, root / "calibration.json")


@pytest.mark.slow
def test_cli_archive_of_real_pmd_files_restarts(shared_data, tmp_path, capsys):
    """A glob over real PMD files, a linear (identity) calibration: detection and repair
    only; exit code 0, outputs mirror the folders, a second run skips every file."""
    pmd = shared_data / PMD
    cal = tmp_path / "pmd.json"
    assert main(["calibrate", "linear", "--like", str(pmd / "S1" / "1.txt"), "--full-scale",
                 "4095", "-o", str(cal)]) == 0  # fmt: skip
    out_dir = str(tmp_path / "out")
    args = ["process", str(pmd / "S*" / "1[01].txt"), "--calibration", str(cal),
            "-o", out_dir, "--repair", "neighbour-mean", "--workers", "2"]  # fmt: skip
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "26 files" in text and "26 processed" in text  # 13 subjects, two files each
    out = load(tmp_path / "out" / "S3" / "11.txt".replace(".txt", ".h5"))
    raw = load(pmd / "S3" / "11.txt")
    assert out.quantity == "raw" and out.n_frames == raw.n_frames
    np.testing.assert_array_equal(out.frames[out.valid], raw.frames[out.valid])
    assert list(out.labels["subject"][:1]) == ["S3"]
    assert main(args) == 0
    assert "0 processed, 26 up to date" in capsys.readouterr().out


def test_cli_single_file_and_errors(sessions, tmp_path, capsys):
    root, _ = sessions
    src = root / "sessions" / "s0.h5"
    assert main(["process", str(src), "--calibration", str(root / "calibration.json"),
                 "-o", str(tmp_path / "one.h5"), "--chunk-frames", "64"]) == 0  # fmt: skip
    assert "wrote" in capsys.readouterr().out
    with h5py.File(tmp_path / "one.h5") as f:
        assert json.loads(f.attrs["meta"])["stages"][-1] == "repair:harmonic"
    assert main(["process", str(tmp_path / "nothing*.h5"), "--calibration",
                 str(root / "calibration.json"), "-o", str(tmp_path / "o")]) == 1  # fmt: skip
    assert "no recordings found" in capsys.readouterr().err
    assert main(["process", str(src), "--calibration", str(src), "-o", str(tmp_path / "z.h5")]) == 1
    assert "a binary file, expected a JSON model file" in capsys.readouterr().err


def test_cli_seat_sessions_write_capacitance_and_the_chain(tmp_path, capsys):
    from texsense.compensation.stages import load_chain

    assert main(["seat-sessions", "-n", "2", "-o", str(tmp_path)]) == 0
    assert "wrote 2 sessions" in capsys.readouterr().out
    chain = load_chain(tmp_path / "calibration.json")
    assert [s.name for s in chain.stages] == ["detect", "convert", "hysteresis", "drift"]
    recs = [load(p) for p in sorted(tmp_path.glob("session-*.h5"))]
    assert len(recs) == 2 and all(r.quantity == "capacitance" for r in recs)
    assert recs[0].labels["subject"][0] != recs[1].labels["subject"][0]
    with pytest.raises(SystemExit) as bad_usage:  # out of its range: a usage error
        main(["seat-sessions", "-n", "0", "-o", str(tmp_path)])
    assert bad_usage.value.code == 2 and "--sessions" in capsys.readouterr().err
