import numpy as np
import pytest

from texsense import Layout, load
from texsense.exceptions import FormatError, ParameterError
from texsense.io.columns_csv import read_columns_csv, write_columns_csv
from texsense.sensor.design import (
    connections,
    design_report,
    elements_per_update,
    lines_between,
    min_electrode_side_cm,
    routing_layers,
    thesis_min_side_cm,
)
from texsense.sim.failures import FailureModel
from texsense.sim.mat import CROSSTALK_AT_HALF, VirtualMat
from texsense.sim.protocols import run_protocol
from texsense.sim.seated import SEAT_FAILURES


def test_calibration_protocol_has_rising_and_three_falling_curves():
    rec = run_protocol("calibration", "textile-6mm", sample_hz=None)
    p = rec.labels["pressure_ncm2"]
    peaks = [k for k in range(1, p.size - 1) if p[k] >= p[k - 1] and p[k] > p[k + 1]]
    assert [round(float(p[k]), 1) for k in peaks] == [10.0, 7.0, 3.0]
    assert rec.quantity == "capacitance" and rec.n_elements == 1
    # the reading is the electrode's capacitance at the specimen's compression (within the
    # converter's 4 fF accuracy and noise)
    from texsense.sensor.electrode import Electrode

    expected = Electrode().capacitance_pF(6.0, rec.labels["compression_mm"])
    np.testing.assert_allclose(rec.frames[:, 0], expected, atol=0.006)


def test_validation_protocol_path():
    rec = run_protocol("validation", "textile-6mm", cycles=2, sample_hz=None)
    p = rec.labels["pressure_ncm2"]
    turns = [float(p[k]) for k in range(1, p.size - 1) if (p[k] - p[k - 1]) * (p[k + 1] - p[k]) < 0]
    np.testing.assert_allclose(turns[:5], [10.0, 1.3, 10.0, 0.0, 1.3], atol=0.05)


def test_steps_are_held_and_segmented():
    rec = run_protocol("steps", "textile-6mm", levels=(2.5, 5.0), hold_s=120)
    seg = rec.labels["segment"]
    assert set(seg.tolist()) == {0, 1}
    for k, level in enumerate((2.5, 5.0)):
        part = seg == k
        platen = rec.labels["platen_mm"][part]
        assert np.ptp(platen[-100:]) == 0  # compression held
        assert rec.labels["pressure_ncm2"][part].max() == pytest.approx(level, rel=0.02)


def test_random_and_cyclic_protocols():
    rec = run_protocol("random", "foam-7mm", duration_s=60, max_ncm2=5)
    p = rec.labels["pressure_ncm2"]
    assert p.min() >= 0 and p.max() <= 5.01
    rec = run_protocol("cyclic", "textile-3mm", p3_ncm2=2.5, duration_s=600)
    assert rec.duration_s >= 600


def test_protocol_errors():
    with pytest.raises(ParameterError, match="unknown protocol 'walk'"):
        run_protocol("walk")
    with pytest.raises(ParameterError, match="protocol 'ramp'"):
        run_protocol("ramp", hold_s=3)
    with pytest.raises(ParameterError, match="unknown spacer preset"):
        run_protocol("ramp", "cardboard")


def test_mat_multiplexing_failures_and_crosstalk():
    mat = VirtualMat.seat(seed=2, failures=FailureModel(permanent_fraction=12 / 96))
    t = np.arange(4) * 1.6
    scan = mat.scan(t, np.full((4, 96), 1.5))
    et = scan.capacitance.element_times
    np.testing.assert_allclose(np.diff(et[0]), mat.cdc.element_time_s)
    assert et[0, -1] - et[0, 0] < 1.6
    # failed elements read 0 pF; the truth says which
    failed = scan.failed
    assert failed.all(axis=0).sum() == 12
    assert np.all(scan.capacitance.frames[failed] == 0.0)
    assert np.all(scan.capacitance.frames[~failed] > 2.0)
    # the session continues: next frames must come later
    with pytest.raises(ParameterError, match="continue"):
        mat.scan(t, np.full((4, 96), 1.5))

    lay = Layout.grid(1, 3, pitch_cm=2.07)
    stripes = VirtualMat(lay, "textile-6mm", architecture="stripes", seed=0)
    alone = VirtualMat(lay, "textile-6mm", architecture="electrodes", seed=0)
    p = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 2.3]])  # right neighbour to ~50 %
    c_s = stripes.scan([0.0, 1.0], p).capacitance.frames
    c_e = alone.scan([0.0, 1.0], p).capacitance.frames
    change = c_s[1, 1] / c_e[1, 1] - 1
    assert change == pytest.approx(CROSSTALK_AT_HALF, rel=0.1)


def test_a_mat_scanned_frame_by_frame_keeps_its_failures():
    """A live virtual source scans one frame per call: the broken elements stay broken and
    an intermittent episode runs on across frames (they were drawn anew at every call)."""
    frames, dt = 600, 0.5
    p = np.full((1, 96), 2.0)
    live = VirtualMat.seat(seed=4, failures=SEAT_FAILURES)
    per_frame = np.vstack([live.scan([k * dt], p).failed for k in range(frames)])
    whole = VirtualMat.seat(seed=4, failures=SEAT_FAILURES)
    at_once = whole.scan(np.arange(frames) * dt, np.repeat(p, frames, axis=0)).failed
    n_perm = round(SEAT_FAILURES.permanent_fraction * 96)
    for failed in (per_frame, at_once):
        assert failed.all(axis=0).sum() == n_perm  # the same 12 elements in every frame
        episodes = np.diff(failed[:, ~failed.all(axis=0)].astype(int), axis=0)
        starts = int((episodes == 1).sum())
        assert starts > 20  # intermittent failures happen frame by frame too
        # an episode lasts 10 s on average (20 frames): runs, not single frames
        assert failed[:, ~failed.all(axis=0)].sum() / starts > 8
    # the same process either way: the share of failed readings agrees
    assert per_frame.mean() == pytest.approx(at_once.mean(), rel=0.25)
    # one call of a whole session draws as it always did (the recorded nights stay the same)
    state_free = SEAT_FAILURES.simulate(
        np.arange(frames) * dt, np.repeat(p, frames, axis=0), np.random.default_rng(1)
    )
    again = SEAT_FAILURES.simulate(
        np.arange(frames) * dt, np.repeat(p, frames, axis=0), np.random.default_rng(1)
    )
    np.testing.assert_array_equal(state_free, again)
    with pytest.raises(ParameterError, match="of a mat of 96 elements, not 3"):
        SEAT_FAILURES.simulate([0.0], np.ones((1, 3)), np.random.default_rng(0), live._failing)


def test_mat_wet_spacer_reads_higher():
    lay = Layout.grid(2, 2)
    dry = VirtualMat(lay, seed=0).scan([0.0], np.ones((1, 4))).capacitance.frames
    wet = VirtualMat(lay, seed=0, water_fraction=0.00275).scan([0.0], np.ones((1, 4)))
    ratio = (wet.capacitance.frames - 0.5) / (dry - 0.5)
    assert np.all((ratio > 1.17) & (ratio < 1.27))


def test_design_rules_reproduce_the_thesis():
    assert lines_between(7.0, 2.0) == 2  # §2.3.2.2
    assert connections(stripes=(8, 12)) == 20 and connections(96) == 97  # eq. 2.2
    assert routing_layers(15, 2) == 3  # the 240-element seat needed three layers
    assert routing_layers(4, 2) == 0  # small arrays route between the electrodes
    assert thesis_min_side_cm(3.0) * 10 > 6.0  # "electrodes greater than 6 mm"
    assert elements_per_update(1 / 1.6) == 96  # 96 elements in 1.6 s
    assert elements_per_update(1 / 1.6, converters=2) == 192
    side = min_electrode_side_cm(3.0, 2.0, stray_pF=0.5)
    from texsense.sensor.electrode import Electrode

    assert float(Electrode(side_cm=side).capacitance_pF(3.0, 0.0)) == pytest.approx(2.0, abs=1e-6)
    r = design_report()
    assert r.connections_single == 241 and r.connections_stripes == 31
    with pytest.raises(ParameterError):
        lines_between(-1)


def test_columns_csv_round_trip_and_errors(tmp_path):
    cols = {"time_s": np.arange(5) * 0.1, "pressure_ncm2": np.random.default_rng(0).random(5)}
    back = read_columns_csv(write_columns_csv(tmp_path / "c.csv", cols))
    for k, v in cols.items():
        np.testing.assert_array_equal(back[k], v)
    bad = tmp_path / "b.csv"
    bad.write_text("time_s,p\n0,1\n0.1,x\n")
    with pytest.raises(FormatError, match="line 3: expected a number, found 'x'"):
        read_columns_csv(bad)
    bad.write_text("time_s,p\n0,1,2\n")
    with pytest.raises(FormatError, match="line 2: expected 2 values"):
        read_columns_csv(bad)
    bad.write_text("0,1\n")
    with pytest.raises(FormatError, match="header of names"):
        read_columns_csv(bad)


def test_simulate_and_design_cli(tmp_path, capsys):
    from texsense.cli import main

    assert (
        main(
            [
                "simulate",
                "calibration",
                "--spacer",
                "foam-7mm",
                "--seed",
                "3",
                "-o",
                str(tmp_path / "c.h5"),
                "--csv",
                str(tmp_path / "c.csv"),
            ]
        )
        == 0
    )
    cols = read_columns_csv(tmp_path / "c.csv")
    assert list(cols) == ["time_s", "compression_mm", "pressure_ncm2", "capacitance_pF"]
    rec = load(tmp_path / "c.h5")
    np.testing.assert_allclose(rec.frames[:, 0], cols["capacitance_pF"], rtol=1e-6)
    assert rec.meta["spacer"] == "foam-7mm" and rec.meta["seed"] == 3
    assert main(["design", "--json"]) == 0
    assert '"routing_layers": 3' in capsys.readouterr().out
    assert main(["simulate", "ramp", "--hold", "3", "--csv", str(tmp_path / "x.csv")]) == 1
    assert main(["simulate", "ramp"]) == 1


@pytest.mark.parametrize("n", [1, 16, 30, 240])
def test_prototypes(n):
    mat = VirtualMat.prototype(n)
    assert mat.layout.n_elements == n
    scan = mat.scan([0.0], np.full((1, n), 2.3))
    assert np.all((scan.capacitance.frames > 1.5) & (scan.capacitance.frames < 5))
    with pytest.raises(ParameterError, match="1, 16, 30 or 240"):
        VirtualMat.prototype(17)
