import numpy as np
import pytest

from texsense import Layout, Recording
from texsense.exceptions import NeighbourIndexError, ParameterError, ShapeError
from texsense.repair import NeighbourMeanRepair


def test_eq_6_14_on_a_checkerboard():
    rr, cc = np.mgrid[0:5, 0:5]
    lay = Layout.grid(5, 5, active=(rr + cc) % 2 == 0)
    frame = np.arange(lay.n_elements, dtype=float) ** 2
    valid = np.ones(lay.n_elements, bool)
    centre = lay.element_at(2, 2)
    valid[centre] = False
    valid[lay.element_at(0, 2)] = False  # one of the four is failed too: n_a = 3
    out, repaired = NeighbourMeanRepair(lay).step(frame, valid)
    available = [lay.element_at(2, 0), lay.element_at(2, 4), lay.element_at(4, 2)]
    assert out[centre] == pytest.approx(frame[available].mean())
    assert repaired.tolist() == (~valid).tolist()


def test_run_equals_step_and_marks_repaired():
    rng = np.random.default_rng(0)
    lay = Layout.grid(6, 7)
    frames = rng.random((30, lay.n_elements)).astype(np.float32).astype(np.float64)
    valid = rng.random(frames.shape) > 0.4
    rec = Recording(frames, np.arange(30.0), lay, valid=valid)
    batch = NeighbourMeanRepair(lay).run(rec)
    stream = NeighbourMeanRepair(lay)
    for t in range(30):
        out, repaired = stream.step(frames[t], valid[t])
        np.testing.assert_array_equal(out.astype(np.float32), batch.frames[t])
        np.testing.assert_array_equal(~repaired, batch.valid[t])
    np.testing.assert_array_equal(batch.frames[valid], frames[valid])


def test_all_neighbours_failed_takes_last_value():
    lay = Layout.grid(1, 3)
    rep = NeighbourMeanRepair(lay)
    rep.step([1.0, 2.0, 3.0], [True, True, True])
    out, _ = rep.step([0.0, 0.0, 0.0], [False, False, False])
    np.testing.assert_array_equal(out, [1.0, 2.0, 3.0])
    assert rep.outcome_.tolist() == [2, 2, 2]
    rep.reset()
    out, _ = rep.step([0.0, 0.0, 0.0], [False, False, False])
    assert np.isnan(out).all() and rep.outcome_.tolist() == [3, 3, 3]


def test_core_errors_map_to_python_exceptions():
    from texsense._core import LocalRepair as Core

    with pytest.raises(NeighbourIndexError, match="out of range"):
        Core("neighbour-mean", 1, np.array([0, 1]), np.array([5]))
    core = Core("neighbour-mean", 2, np.array([0, 0, 0]), np.array([], dtype=np.int64))
    with pytest.raises(ShapeError, match="2 elements per frame"):
        core.run(np.zeros((1, 3)), np.ones((1, 3), bool))
    with pytest.raises(ParameterError):
        NeighbourMeanRepair(Layout.grid(2, 2)).step(np.zeros(3), np.ones(3, bool))
