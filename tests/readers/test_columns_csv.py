"""Column tables: the same base as the recording readers (blocks, cuts, accept_truncated)."""

import numpy as np
import pytest

from texsense.exceptions import FormatError
from texsense.io.columns_csv import ColumnsReader, read_columns_csv, write_columns_csv


@pytest.fixture
def table(tmp_path):
    rng = np.random.default_rng(2)
    cols = {"time_s": np.arange(50) * 0.1, "pressure_ncm2": rng.random(50), "c_pF": rng.random(50)}
    return cols, write_columns_csv(tmp_path / "t.csv", cols)


def test_blocks_equal_whole_and_round_trip(table):
    cols, path = table
    whole = read_columns_csv(path)
    for k, v in cols.items():
        np.testing.assert_array_equal(whole[k], v)
    for rows in (1, 7, 50, 60):
        with ColumnsReader(path) as reader:
            blocks = list(reader.blocks(rows))
        for k in cols:
            np.testing.assert_array_equal(np.concatenate([b[k] for b in blocks]), whole[k])


@pytest.mark.parametrize("cut", ["line end", "in a line", "inside the last number"])
def test_cut_table_is_refused_or_read_with_a_warning(table, caplog, cut):
    cols, path = table
    data = path.read_bytes()
    keep = {
        "line end": b"\n".join(data.split(b"\n")[:-11]) + b"\n",  # 10 rows gone
        "in a line": data[: len(data) // 2],
        "inside the last number": data[:-3],
    }[cut]
    path.write_bytes(keep)
    with pytest.raises(FormatError, match=r"t\.csv: truncated"):
        read_columns_csv(path)
    part = read_columns_csv(path, accept_truncated=True)
    n = part["time_s"].size
    assert n < 50 and "t.csv" in caplog.text
    np.testing.assert_array_equal(part["pressure_ncm2"], cols["pressure_ncm2"][:n])


def test_non_finite_values_are_counted(tmp_path, caplog):
    path = tmp_path / "n.csv"
    path.write_text("time_s,p\n0,1\n0.1,nan\n0.2,inf\n")
    assert np.isnan(read_columns_csv(path)["p"][1])
    assert "2 value(s) are not finite" in caplog.text
