"""Every command reads what texsense writes (issue 25 item 4): the column tools read texsense
recordings as well as column CSVs, and posture reads a folder of recordings."""

import json
import logging

import numpy as np
import pytest

from texsense import Layout, Recording, load
from texsense.cli import main
from texsense.compensation.hysteresis.sampling import coarse_turns, sampling_warning
from texsense.io import read_folder
from texsense.io.columns import is_columns_csv, read_columns, write_columns
from texsense.io.columns_csv import write_columns_csv


@pytest.fixture(scope="module")
def steps(tmp_path_factory):
    """Held steps as HDF5 and as CSV, from one simulation."""
    folder = tmp_path_factory.mktemp("steps")
    h5, csv = folder / "steps.h5", folder / "steps.csv"
    args = ["simulate", "steps", "--levels", "2.5,5", "--hold", "300", "-o", str(h5)]
    assert main([*args, "--csv", str(csv)]) == 0
    return h5, csv


def test_an_hdf5_record_reads_as_the_same_columns_as_its_csv(steps):
    h5, csv = steps
    a, b = read_columns(h5), read_columns(csv)
    for name in ("time_s", "compression_mm", "pressure_ncm2", "capacitance_pF"):
        np.testing.assert_allclose(a[name], b[name], rtol=1e-6, err_msg=name)  # float32 frames
    assert is_columns_csv(csv) and not is_columns_csv(h5)


def test_drift_fit_gives_the_same_gamma_from_hdf5_and_csv(steps, capsys):
    h5, csv = steps
    results = []
    for path in (h5, csv):
        assert main(["drift", "fit", str(path), "--json"]) == 0
        results.append(json.loads(capsys.readouterr().out)["gamma_common"])
    assert results[0] == pytest.approx(results[1], rel=1e-6)
    assert results[0] < 0  # the virtual spacer relaxes at held compression


def test_a_table_whose_named_columns_are_there_is_a_table_whatever_else_it_holds(
    steps, tmp_path, capsys
):
    """An export that starts with time_s and holds a column without a unit (here the
    specimen) was taken for a wide CSV; drift fit names its columns, so it is a table."""
    _, csv = steps
    cols = read_columns(csv)
    export = tmp_path / "export.csv"
    names = ("time_s", "compression_mm", "pressure_ncm2")
    rows = zip(*(cols[n].tolist() for n in names), strict=True)
    text = "time_s,compression_mm,pressure_ncm2,specimen\n"
    export.write_text(text + "".join(f"{t!r},{c!r},{p!r},7\n" for t, c, p in rows), "utf-8")
    assert not is_columns_csv(export) and is_columns_csv(export, names)
    results = []
    for path in (csv, export):
        assert main(["drift", "fit", str(path), "--json"]) == 0
        results.append(json.loads(capsys.readouterr().out)["gamma_common"])
    assert results[1] == pytest.approx(results[0], rel=1e-9)


def test_hysteresis_fit_apply_on_hdf5_writes_a_recording(tmp_path, capsys):
    cal, val = tmp_path / "cal.h5", tmp_path / "val.h5"
    assert main(["simulate", "calibration", "--seed", "1", "-o", str(cal)]) == 0
    assert main(["simulate", "ramp", "--cycles", "2", "--seed", "1", "-o", str(val)]) == 0
    assert main(["hysteresis", "fit", str(cal), "-o", str(tmp_path / "m.json")]) == 0
    out = tmp_path / "out.h5"
    assert main(["hysteresis", "apply", str(tmp_path / "m.json"), str(val), "-o", str(out)]) == 0
    assert "RMSE" in capsys.readouterr().out
    rec = load(out)
    assert (rec.quantity, rec.unit, rec.n_elements) == ("pressure", "N/cm2", 1)
    truth = rec.labels["pressure_ncm2"]
    assert np.sqrt(np.mean((rec.frames[:, 0] - truth) ** 2)) < 0.3  # compensated, N/cm²
    assert read_columns(out)["pressure_ncm2_model"].size == rec.n_frames  # and back


def test_write_columns_csv_or_hdf5(tmp_path):
    cols = {"time_s": [0.0, 0.1, 0.2], "force_n": [1.0, 2.0, np.nan]}
    write_columns(tmp_path / "a.csv", cols)
    assert read_columns(tmp_path / "a.csv")["force_n"][1] == 2.0
    write_columns(tmp_path / "a.h5", cols, values="force_n")
    rec = load(tmp_path / "a.h5")
    assert (rec.quantity, rec.unit) == ("force", "N")
    assert rec.valid[:, 0].tolist() == [True, True, False]


def test_a_column_table_without_time_is_a_table(tmp_path):
    write_columns_csv(tmp_path / "r.csv", {"displacement_mm": [0, 1], "force_n": [0, 2]})
    (tmp_path / "r.csv").write_text("displacement_mm,force_n\n0,0\n1,2\n", encoding="utf-8")
    assert is_columns_csv(tmp_path / "r.csv")
    assert read_columns(tmp_path / "r.csv")["force_n"].tolist() == [0.0, 2.0]


def _triangle(hz: float, speed: float = 0.83) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(0, 120, 1 / hz)
    return t, 4 - np.abs((t * speed) % 8 - 4)


def test_sharp_reversals_between_samples_are_found_and_a_rate_named():
    t, u = _triangle(10.0)
    c = coarse_turns(u, t)
    assert c.turns >= 20 and c.unresolved >= c.turns // 2
    assert 0.02 < c.max_missed <= 0.83 / 10 / 2 + 1e-9  # at most half a sample's travel
    assert c.needed_hz > 10
    t, u = _triangle(c.needed_hz * 1.01)
    assert coarse_turns(u, t).unresolved == 0  # the rate named resolves them


def test_smooth_reversals_are_resolved_at_a_low_rate():
    t = np.arange(0, 120, 0.1)
    u = 2 - 2 * np.cos(2 * np.pi * t / 20)  # 200 samples a cycle
    assert coarse_turns(u, t).unresolved == 0
    assert sampling_warning(u, t) is None


def test_validate_warns_at_10_hz_and_not_at_50_hz(tmp_path, caplog):
    model = tmp_path / "m.json"
    assert main(["simulate", "calibration", "--seed", "1", "-o", str(tmp_path / "c.h5")]) == 0
    assert main(["hysteresis", "fit", str(tmp_path / "c.h5"), "-o", str(model)]) == 0
    for hz, warned in (("10", True), ("50", False)):
        val = tmp_path / f"v{hz}.h5"
        args = ["simulate", "sawtooth", "--seed", "1", "--sample-hz", hz, "-o", str(val)]
        assert main(args) == 0
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="texsense"):
            assert main(["hysteresis", "validate", str(model), str(val)]) == 0
        lines = [r.getMessage() for r in caplog.records if "between samples" in r.getMessage()]
        assert bool(lines) == warned, (hz, lines)
        if warned:
            assert "at 10 Hz" in lines[0] and "sample at 50 Hz or more" in lines[0]


def _session(tmp_path, name, subject, n_elements=4):
    rec = Recording(
        np.full((6, n_elements), float(len(subject)), dtype=np.float32),
        np.arange(6) * 0.5,
        Layout.grid(1, n_elements),
        labels={"posture": [1, 1, 2, 2, 3, 3], "subject": [subject] * 6},
    )
    return rec.save(tmp_path / name)


def test_a_folder_of_recordings_reads_as_one(tmp_path):
    _session(tmp_path, "session-10.h5", "B")
    _session(tmp_path, "session-9.h5", "A")
    (tmp_path / "calibration.json").write_text("{}", encoding="utf-8")
    rec = read_folder(tmp_path)
    assert rec.n_frames == 12
    assert rec.labels["subject"].tolist() == ["A"] * 6 + ["B"] * 6  # natural order
    assert set(rec.labels["file"]) == {"session-9.h5", "session-10.h5"}
    assert load(tmp_path).equals(rec)


def test_a_column_table_reads_as_a_one_element_recording(steps, tmp_path):
    h5, csv = steps
    rec = load(csv)  # the reverse: what the column tools read, the recording commands read
    assert (rec.n_elements, rec.quantity, rec.unit) == (1, "capacitance", "pF")
    np.testing.assert_allclose(rec.frames[:, 0], load(h5).frames[:, 0], rtol=1e-6)
    assert set(rec.labels) == {"compression_mm", "pressure_ncm2"}
    assert main(["convert", str(csv), str(tmp_path / "back.h5")]) == 0
    assert load(tmp_path / "back.h5").n_frames == rec.n_frames
    again = read_columns(tmp_path / "back.h5")  # and back to the same columns
    for name, column in read_columns(csv).items():
        np.testing.assert_allclose(again[name], column, rtol=1e-6, err_msg=name)


def test_a_folder_of_files_that_each_start_at_zero_runs_on_in_time(tmp_path):
    _session(tmp_path, "a.h5", "A")
    _session(tmp_path, "b.h5", "B")
    rec = read_folder(tmp_path)
    assert np.all(np.diff(rec.times) > 0)
    assert rec.times[6] == pytest.approx(rec.times[5] + 0.5)  # one frame period later
