"""The virtual bed (texsense.sim.bed), the at-risk regions and the turning schedule
(texsense.apps.bed), and the monitor's bed mode."""

import asyncio
import copy
import itertools

import numpy as np
import pytest

from texsense import Layout
from texsense.apps.bed import BedWatch, TurningSchedule, body_axis, find_regions
from texsense.apps.posture.features import mirror_frames
from texsense.exceptions import ParameterError
from texsense.sim.bed import (
    BED_PITCH_CM,
    POSITIONS,
    SIDES,
    Placement,
    Sleeper,
    bed_layout,
    bed_session,
    lying_pressure,
    night_plan,
    prominences,
)

LAY = bed_layout()


def test_the_mat_is_a_common_bed_mat_size():
    assert LAY.shape == (64, 32) and BED_PITCH_CM == 2.54
    x0, x1, y0, y1 = LAY.extent_cm
    assert 160 < y1 - y0 < 165 and 80 < x1 - x0 < 83


def test_total_force_is_the_body_weight_when_the_body_is_on_the_mat():
    small = Sleeper(height_cm=150, weight_kg=60, head_cm=5)
    for position in POSITIONS:
        p = lying_pressure(LAY, position, small)
        assert p.sum() * BED_PITCH_CM**2 == pytest.approx(60 * 9.81, rel=0.01), position
        assert np.all(p >= 0)
    tall = Sleeper(height_cm=195, weight_kg=60, head_cm=0)  # the heels are off the mat
    lost = 60 * 9.81 - lying_pressure(LAY, "supine", tall).sum() * BED_PITCH_CM**2
    assert lost > 5 and "heel-l" not in prominences("supine", tall)


def test_peak_pressures_are_those_of_people_on_a_mattress():
    mmhg = {
        pos: lying_pressure(LAY, pos).max() * 75.006
        for pos in ("supine", "left", "prone, head left")
    }
    assert 50 < mmhg["supine"] < 100 and 80 < mmhg["left"] < 140 and mmhg["prone, head left"] < 80


def test_right_is_the_mirror_image_of_left():
    for a, b in (("left", "right"), ("left, foetal", "right, foetal")):
        left = lying_pressure(LAY, a)
        right = lying_pressure(LAY, b)
        np.testing.assert_allclose(mirror_frames(left[None], LAY)[0], right, atol=1e-9)
    assert set(SIDES) == set(POSITIONS.values())


def test_people_differ_and_a_take_moves_the_body():
    a, b = Sleeper.random(0), Sleeper.random(1)
    assert a != b and a == Sleeper.random(0)
    p0 = lying_pressure(LAY, "supine", a)
    moved = lying_pressure(LAY, "supine", a, Placement(along_cm=5.0))
    assert not np.allclose(p0, moved) and not np.allclose(p0, lying_pressure(LAY, "supine", b))
    y0 = prominences("supine", a)["sacrum"][1]
    assert prominences("supine", a, Placement(along_cm=5.0))["sacrum"][1] == pytest.approx(y0 + 5)


def test_unknown_positions_and_bad_plans_are_refused():
    with pytest.raises(ParameterError, match="unknown position 'upside down'"):
        lying_pressure(LAY, "upside down")
    with pytest.raises(ParameterError, match="unknown position"):
        bed_session(Sleeper(), [("standing", 10.0)])
    with pytest.raises(ParameterError, match="> 0 s"):
        bed_session(Sleeper(), [("supine", 0.0)])


def test_a_session_turns_sits_up_and_leaves():
    plan = [("supine", 20.0), ("left", 20.0), ("sitting up", 10.0), ("out", 10.0)]
    s = bed_session(Sleeper.random(2), plan, seed=1)
    lab = s.truth.labels
    assert list(dict.fromkeys(lab["side"])) == ["supine", "transition", "left", "sitting", "out"]
    assert not lab["hold"][lab["side"] == "transition"].any()
    assert np.all(s.truth.frames[lab["side"] == "out"] == 0)
    assert len(s.prominences) == s.truth.n_frames and "sacrum" in s.prominences[0]
    rng = np.random.default_rng(0)
    plan = night_plan(rng, 10, 60.0, sit_every=5, out_every=10)
    sides = [POSITIONS.get(p, p) for p, _ in plan]
    assert sides.count("sitting") == 2 and sides[-1] == "out"
    lying = [s for s in sides if s not in ("sitting", "out")]
    assert all(a != b for a, b in itertools.pairwise(lying))  # every move a turn


@pytest.mark.parametrize("seed", range(3))
def test_regions_are_found_where_the_prominences_are(seed):
    """Every prominence on the mat is found within 3 cm, for random people and takes."""
    rng = np.random.default_rng(seed)
    for i in range(4):
        person = Sleeper.random(i, seed=seed)
        for position, side in POSITIONS.items():
            place = Placement.random(rng)
            found = find_regions(lying_pressure(LAY, position, person, place), LAY, side)
            for name, (x, y) in prominences(position, person, place).items():
                assert name in found, (position, name)
                r = found[name]
                assert np.hypot(r.x_cm - x, r.y_cm - y) < 3.0, (position, name)
                assert r.peak >= r.mean > 0 and r.elements


def test_region_risk_follows_the_threshold():
    p = lying_pressure(LAY, "supine")
    low = find_regions(p, LAY, "supine", threshold=10, unit="mmHg")
    high = find_regions(p, LAY, "supine", threshold=200, unit="mmHg")
    assert all(r.at_risk for r in low.values()) and not any(r.at_risk for r in high.values())
    d = low["sacrum"].to_dict()
    assert d["peak_mmhg"] == pytest.approx(low["sacrum"].peak * 75.006, abs=0.1)


def test_regions_of_an_empty_bed_and_bad_input():
    assert find_regions(np.zeros(LAY.n_elements), LAY, "supine") == {}
    assert body_axis(np.zeros(LAY.n_elements), LAY) is None
    with pytest.raises(ParameterError, match="unknown side 'standing'"):
        find_regions(np.zeros(LAY.n_elements), LAY, "standing")
    with pytest.raises(ParameterError, match="one frame of 2048"):
        find_regions(np.zeros(10), LAY, "supine")
    with pytest.raises(ParameterError, match="grid layout"):
        find_regions(np.zeros(2), Layout.points([[0, 0], [1, 1]]), "supine")
    with pytest.raises(ParameterError, match="pressure unit"):
        find_regions(np.zeros(LAY.n_elements), LAY, "supine", unit="pF")


def test_body_axis_follows_a_rotated_body():
    for angle in (-10.0, 0.0, 10.0):
        person = Sleeper(angle_deg=angle, head_cm=5)
        _, axis, length = body_axis(lying_pressure(LAY, "supine", person), LAY)
        assert axis[1] > 0  # from the head end
        assert np.degrees(np.arctan2(axis[0], axis[1])) == pytest.approx(angle, abs=3.0)
        assert 140 < length < 175


def run(schedule, steps):
    """(t, side) steps -> [(kind, t)]."""
    return [(e.kind, e.t) for t, side in steps for e in schedule.step(side, float(t))]


def test_turning_schedule_counts_turns_time_per_side_and_alerts():
    s = TurningSchedule(interval_min=30, settle_s=60)
    steps = [(t, "supine") for t in range(0, 1200, 10)]
    steps += [(t, "left") for t in range(1200, 3600, 10)]  # left for 40 min
    events = run(s, steps)
    assert events == [("in-bed", 0.0), ("turn", 1200.0), ("turn-due", 3000.0)]
    st = s.status(3590.0)
    assert st["side"] == "left" and st["turns"] == 1 and st["turn_due"]
    assert st["since_turn_s"] == pytest.approx(2390.0) and st["due_in_s"] == pytest.approx(-590.0)
    assert st["time_per_side_s"]["supine"] == pytest.approx(1260.0)  # until the turn counted
    assert sum(st["time_per_side_s"].values()) == pytest.approx(3590.0)
    assert run(s, [(3600 + k * 10, "right") for k in range(7)]) == [
        ("turn", 3600.0), ("turn-done", 3660.0)
    ]  # fmt: skip
    assert not s.status(3660.0)["turn_due"]


def test_a_side_corrected_on_getting_into_bed_gets_the_time_held_on_it():
    # the virtual night's first frame in bed is "transition", then "right": the 60 s of
    # settling on the right were counted to "transition" (1 min 10 s of a 4 min stay, 30 %,
    # where the label says 10 s)
    s = TurningSchedule(interval_min=120, settle_s=60)
    steps = [(t, None) for t in range(0, 300, 10)] + [(300, "transition")]
    steps += [(t, "right") for t in range(310, 540, 10)]
    assert run(s, steps) == [("in-bed", 300.0)] and s.turns == 0
    times = s.status(530.0)["time_per_side_s"]
    assert times["transition"] == pytest.approx(10.0) and times["right"] == pytest.approx(220.0)


def test_a_roll_that_comes_back_is_not_a_turn():
    s = TurningSchedule(interval_min=15, settle_s=60)
    steps = [(t, "supine") for t in range(0, 600, 10)]
    steps += [(t, "left") for t in range(600, 640, 10)]  # 40 s on the side, then back
    steps += [(t, "supine") for t in range(640, 960, 10)]
    assert run(s, steps) == [("in-bed", 0.0), ("turn-due", 900.0)]
    assert s.turns == 0


def test_out_of_bed_restarts_the_clock_only_after_the_offload_time():
    s = TurningSchedule(interval_min=15, settle_s=30, offload_min=2)
    steps = [(t, "supine") for t in range(0, 600, 10)]
    steps += [(t, None) for t in range(600, 660, 10)]  # 1 min out: not offloaded
    steps += [(t, "supine") for t in range(660, 700, 10)]
    assert run(s, steps) == [("in-bed", 0.0)]
    assert s.status(690.0)["since_turn_s"] == pytest.approx(690.0)
    steps = [(t, "out") for t in range(700, 900, 10)] + [(t, "left") for t in range(900, 950, 10)]
    assert run(s, steps) == [("out-of-bed", 820.0), ("in-bed", 900.0)]
    assert s.status(940.0)["since_turn_s"] == pytest.approx(40.0) and s.turns == 0


def test_out_of_bed_events_and_the_alert_closing_by_offload():
    s = TurningSchedule(interval_min=15, settle_s=30, offload_min=1)
    steps = [(t, "prone") for t in range(0, 960, 10)]
    steps += [(t, None) for t in range(960, 1100, 10)]
    steps += [(t, "right") for t in range(1100, 1200, 10)]
    assert run(s, steps) == [
        ("in-bed", 0.0), ("turn-due", 900.0), ("out-of-bed", 1020.0), ("turn-done", 1020.0),
        ("in-bed", 1100.0),
    ]  # fmt: skip
    assert s.status(1190.0)["since_turn_s"] == pytest.approx(90.0)


def test_turning_schedule_parameters_are_checked():
    with pytest.raises(ParameterError, match="15-480"):
        TurningSchedule(interval_min=5)
    with pytest.raises(ParameterError, match=">= 0"):
        TurningSchedule(settle_s=-1)
    with pytest.raises(ParameterError, match="grid layout"):
        BedWatch(Layout.points([[0, 0], [1, 1]]))
    with pytest.raises(ParameterError, match="unit"):
        BedWatch(LAY, unit="pF")


def test_bed_watch_reports_regions_for_the_side():
    w = BedWatch(LAY, interval_min=15)
    p = lying_pressure(LAY, "left")
    assert [e.kind for e in w.step(p, "left", 0.0)] == ["in-bed"]
    st = w.status(0.0)
    assert {r["name"] for r in st["regions"]} == {"shoulder", "trochanter", "knee", "ankle"}
    w.step(np.zeros(LAY.n_elements), None, 1.0)
    with pytest.raises(TypeError, match="the time comes last"):
        w.step(2.0, p, "left")  # the order of before: time first
    assert w.status(1.0)["regions"] == []


@pytest.fixture(scope="module")
def small_bed_model():
    from texsense.apps.posture.training import train_virtual_bed_model

    return train_virtual_bed_model(people=3, hold_s=6.0)


@pytest.fixture(scope="module")
def bed_frames():
    """400 frames of a person on the virtual bed (turning, sitting up, away) and the side
    they lay on at each."""
    from texsense.monitor.virtual import VirtualBedSource

    src = VirtualBedSource(speed=0, hold_s=90, positions_per_stay=4, away_s=60, seed=3)
    frames, truth = [], []

    async def go():
        async for f in src.frames():
            frames.append(f)
            truth.append(src.side)
            if len(frames) >= 400:
                break

    asyncio.run(go())
    return src.layout, frames, truth


def bed_monitor(layout, model):
    from texsense.calibration.workflows import bed_calibration
    from texsense.compensation.pipeline import Pipeline
    from texsense.monitor import Monitor
    from texsense.monitor.sources import Source

    src = Source()
    src.layout, src.quantity, src.unit, src.name = layout, "capacitance", "pF", "bed"
    return Monitor(src, pipeline=Pipeline(bed_calibration(), layout), posture_model=model,
                   bed=BedWatch(layout, interval_min=15, settle_s=20))  # fmt: skip


@pytest.mark.slow
def test_monitor_on_the_virtual_bed_reports_sides_turns_and_regions(small_bed_model, bed_frames):
    assert set(small_bed_model.classes_) == set(SIDES)
    layout, frames, truth = bed_frames
    m = bed_monitor(layout, small_bed_model)
    snaps = [m.process(copy.copy(f)) for f in frames]
    kinds = [e["kind"] for e in m.store.events(m.session_id)]
    assert "in-bed" in kinds and kinds.count("turn") >= 2
    lying = [k for k, s in enumerate(snaps) if truth[k] not in (None, "transition")]
    right = [snaps[k]["posture"] and snaps[k]["posture"]["label"] == truth[k] for k in lying]
    assert np.mean(right) > 0.8
    regions = [r["name"] for k in lying for r in snaps[k]["bed"]["regions"]]
    assert regions and snaps[-1]["bed"]["time_per_side_s"]


def test_monitor_refuses_a_bed_without_a_side_model():
    from texsense.apps.posture import FeatureSet, PostureModel
    from texsense.calibration.workflows import bed_calibration
    from texsense.compensation.pipeline import Pipeline
    from texsense.monitor import Monitor
    from texsense.monitor.virtual import VirtualBedSource

    src = VirtualBedSource(speed=0)
    pipe = Pipeline(bed_calibration(), src.layout)
    with pytest.raises(ParameterError, match="needs a posture model"):
        Monitor(src, pipeline=pipe, bed=BedWatch(src.layout))
    frames = np.vstack([lying_pressure(LAY, "supine"), lying_pressure(LAY, "left")])
    other = PostureModel(FeatureSet(("centre",)), LAY).fit(frames, ["upright", "supine"])
    with pytest.raises(ParameterError, match="also knows upright"):
        Monitor(src, pipeline=pipe, posture_model=other, bed=BedWatch(src.layout))


def test_a_wrong_first_side_on_getting_into_bed_is_corrected_not_counted():
    s = TurningSchedule(interval_min=15, settle_s=60)
    steps = [(0, None), (10, "prone")] + [(t, "supine") for t in range(20, 400, 10)]
    assert run(s, steps) == [("in-bed", 10.0)]
    st = s.status(390.0)
    assert st["side"] == "supine" and st["turns"] == 0 and st["since_turn_s"] == 380.0


def test_monitor_command_refuses_a_bed_mode_it_cannot_run(tmp_path, capsys):
    from conftest import free_port
    from texsense import Recording
    from texsense.cli import main
    from texsense.io import save

    path = tmp_path / "bed.h5"
    save(Recording(np.ones((3, 16)), [0.0, 1.0, 2.0], Layout.grid(4, 4), "pressure", "N/cm2"),
         path)  # fmt: skip
    base = ["monitor", "--source", f"replay:{path}", "--port", str(free_port()), "--bed"]
    assert main(base) != 0
    assert "--bed needs --model" in capsys.readouterr().err
    assert main([*base, "--no-posture"]) != 0
    assert "drop --no-posture" in capsys.readouterr().err


@pytest.mark.slow
def test_a_bed_s_skimmed_frames_give_the_schedule_and_exposure_of_every_frame(
    small_bed_model, bed_frames
):
    """A station behind follows the frames it skims (Monitor.follow, issue 38): on a bed the
    side vote and the turning schedule too, so its turns, events and exposure are those of
    processing every frame (half of them skimmed at random)."""
    layout, frames, _ = bed_frames
    whole, skimming = bed_monitor(layout, small_bed_model), bed_monitor(layout, small_bed_model)
    skims = np.random.default_rng(38).random(len(frames)) < 0.5
    skims[-1] = False
    for k, f in enumerate(frames):
        whole.process(copy.copy(f), wall=1000.0 + k)
        if skims[k]:
            assert skimming.follow(copy.copy(f), 1000.0 + k)
        else:
            skimming.process(copy.copy(f), wall=1000.0 + k)
    events = [
        [(e["kind"], e["t"]) for e in m.store.events(m.session_id)] for m in (whole, skimming)
    ]
    assert [k for k, _ in events[0]].count("turn") >= 2
    assert events[0] == events[1]
    assert whole.bed.schedule.state() == skimming.bed.schedule.state()
    np.testing.assert_array_equal(whole.tracker.exposure_s, skimming.tracker.exposure_s)
    assert skimming.frames == len(frames) - skims.sum()
