import numpy as np
import pytest

from texsense import Layout
from texsense.exceptions import ParameterError


def test_grid_coordinates_numbering_and_empty_cells():
    active = np.ones((3, 4), bool)
    active[1, 1] = False
    lay = Layout.grid(3, 4, pitch_cm=(2.0, 1.0), active=active)
    assert lay.n_elements == 11
    assert lay.kind == "grid"
    assert lay.pitch_cm == (2.0, 1.0)
    # element 4 is row 1, col 0 (row-major over active cells); x from cols, y from rows
    assert lay.element_at(1, 0) == 4
    assert lay.element_at(1, 1) == -1
    np.testing.assert_allclose(lay.xy_cm[4], [0.5, 3.0])
    np.testing.assert_allclose(lay.area_cm2, 2.0)
    assert lay.extent_cm == (0.0, 4.0, 0.0, 6.0)
    np.testing.assert_array_equal(lay.active, active)


def test_to_grid_and_back():
    active = np.array([[True, False], [True, True]])
    lay = Layout.grid(2, 2, active=active)
    maps = lay.to_grid(np.array([[1.0, 2.0, 3.0]]))
    assert maps.shape == (1, 2, 2)
    assert np.isnan(maps[0, 0, 1])
    np.testing.assert_array_equal(lay.from_grid(maps), [[1.0, 2.0, 3.0]])


def test_four_neighbours_on_full_grid():
    lay = Layout.grid(3, 3)
    assert sorted(lay.neighbours_of(4).tolist()) == [1, 3, 5, 7]
    assert sorted(lay.neighbours_of(0).tolist()) == [1, 3]


def test_checkerboard_neighbours_skip_one_empty_cell():
    # thesis §6.2.1: 96 of 240 elements active in a checkerboard; neighbours are 2 cells away
    rr, cc = np.mgrid[0:5, 0:5]
    active = (rr + cc) % 2 == 0
    lay = Layout.grid(5, 5, active=active)
    centre = lay.element_at(2, 2)
    expected = {
        lay.element_at(2, 0),
        lay.element_at(2, 4),
        lay.element_at(0, 2),
        lay.element_at(4, 2),
    }
    assert set(lay.neighbours_of(centre).tolist()) == expected


def test_gap_of_two_cells_separates_pads():
    active = np.ones((1, 6), bool)
    active[0, 2:4] = False  # Tekscan-like 'B' stripe of 2 cells
    lay = Layout.grid(1, 6, active=active)
    assert lay.neighbours_of(lay.element_at(0, 1)).tolist() == [lay.element_at(0, 0)]
    lay0 = Layout.grid(1, 6, active=active, neighbour_gap=2)
    assert lay.element_at(0, 4) in lay0.neighbours_of(lay.element_at(0, 1)).tolist()


def test_equal_areas_4_and_16():
    lay = Layout.grid(8, 8, pitch_cm=1.0)
    a4 = lay.equal_areas(4)
    assert list(a4) == ["a1", "a2", "a3", "a4"]
    assert all(len(v) == 16 for v in a4.values())
    assert lay.element_at(0, 0) in a4["a1"] and lay.element_at(7, 7) in a4["a4"]
    a16 = lay.equal_areas(16)
    assert sum(len(v) for v in a16.values()) == 64
    assert lay.element_at(2, 4) in a16["a7"]  # row band 1, column band 2 -> 1 * 4 + 2 + 1
    with pytest.raises(ParameterError, match="square number"):
        lay.equal_areas(5)


def test_regions_and_dict_round_trip():
    lay = Layout.grid(4, 4).with_regions({"left": [0, 4, 8, 12]})
    lay = lay.with_regions(lay.equal_areas(4))
    back = Layout.from_dict(lay.to_dict())
    assert back == lay
    assert back.regions["left"].tolist() == [0, 4, 8, 12]


def test_points_layout():
    lay = Layout.points([[0, 0], [3, 4]], size_cm=2.0, names=["a", "b"])
    assert lay.kind == "points" and lay.shape is None
    np.testing.assert_allclose(lay.area_cm2, 4.0)
    assert lay.names == ("a", "b")
    assert lay.neighbours_of(0).size == 0
    with pytest.raises(ParameterError, match="grid layout"):
        lay.to_grid([1.0, 2.0])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"rows": 0, "cols": 3}, "rows and cols"),
        ({"rows": 2, "cols": 2, "pitch_cm": -1.0}, "pitch_cm must be positive"),
        ({"rows": 2, "cols": 2, "active": np.ones((3, 3), bool)}, "active"),
        ({"rows": 2, "cols": 2, "neighbour_gap": -1}, "neighbour_gap"),
    ],
)
def test_bad_grid_parameters(kwargs, message):
    with pytest.raises(ParameterError, match=message):
        Layout.grid(**kwargs)


def test_bad_constructor_input():
    with pytest.raises(ParameterError, match="xy_cm"):
        Layout(np.zeros((3, 3)), (1, 1))
    with pytest.raises(ParameterError, match="size"):
        Layout(np.zeros((2, 2)), (0.0, 1.0))
    with pytest.raises(ParameterError, match="region 'r'"):
        Layout(np.zeros((2, 2)), (1, 1), regions={"r": [5]})
    with pytest.raises(ParameterError, match="neighbours"):
        Layout(np.zeros((2, 2)), (1, 1), neighbours=([0, 1, 1], [7]))
