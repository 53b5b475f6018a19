"""Column tables: the same base as the recording readers (blocks, cuts, accept_truncated)."""

import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

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


# float() reads each; 1e300 and -1e300 lie beyond any sensor (read as not a number), 1e15 not
_GOOD = ["1", "-2.5", " 3e2 ", "nan", "inf", "1_0", "+7", "\u0661", "1e300", "-1e300", "1e15"]
_BAD = ["", "x", "1.2.3", "0x1"]


def _line(n: int) -> st.SearchStrategy[list[str]]:
    """Mostly n numbers; now and then one too many or too few, or a token that is no number."""
    token = st.one_of(st.sampled_from(_GOOD), st.sampled_from(_GOOD), st.sampled_from(_BAD))
    length = st.sampled_from([n] * 6 + [max(1, n - 1), n + 1])
    good = st.sampled_from(_GOOD)  # a line of the wrong length holds numbers only
    return length.flatmap(lambda k: st.lists(token if k == n else good, min_size=k, max_size=k))


#: the columns a generated table draws its names from, and each one's ceiling
_NAMES = {"c": 1e15, "pressure_ncm2": 1e5, "time_s": np.inf}


def _by_line(text: str, n: int, ceilings: list[float]) -> tuple[np.ndarray | None, str | None]:
    """What the table's rows are when each line is read on its own (the rule the reader
    states): the values, or the start of the error: the first line that is not n numbers (or
    an empty line inside the table), or a last line without its line end that is not a row
    (a table cut in the middle of a line)."""
    rows, blank = [], None
    body = text.split("\n")[1:]
    for number, line in enumerate(body, start=2):
        if not line.strip():  # empty lines end a table; one inside it is an error
            blank = blank or number
            continue
        if blank is not None:
            return None, f"line {blank}: "
        tokens = line.split(",")
        try:
            assert len(tokens) == n
            row = [float(t) for t in tokens]
            # a finite value beyond its column's ceiling is read as not a number
            rows.append([v if abs(v) <= c or not np.isfinite(v) else np.nan
                         for v, c in zip(row, ceilings, strict=True)])  # fmt: skip
        except (AssertionError, ValueError):
            cut = number == len(body) + 1  # the last line, without its line end
            return (
                None,
                f"truncated: the file ends in the middle of line {number}"
                if cut
                else f"line {number}: ",
            )
    return np.array(rows, dtype=np.float64).reshape(len(rows), n), None


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data(), n=st.integers(1, 4), rows=st.integers(1, 9))
def test_blocks_read_what_each_line_reads_or_name_its_first_bad_line(tmp_path, data, n, rows):
    """The reader parses a block of lines at once; the values, or the line its error names,
    are those of reading each line on its own, whatever the block size (and a value beyond
    its column's ceiling is read as not a number on either path)."""
    blank = st.just([" "])  # an empty line: the end of the table, or an error inside it
    lines = data.draw(st.lists(st.one_of(_line(n), _line(n), _line(n), blank), max_size=40))
    kinds = data.draw(st.lists(st.sampled_from(list(_NAMES)), min_size=n, max_size=n))
    names = [f"{kind}{k}" if kind == "c" else f"x{k}_{kind}" for k, kind in enumerate(kinds)]
    ceilings = [_NAMES[kind] for kind in kinds]
    text = ",".join(names) + "\n" + "".join(",".join(t) + "\n" for t in lines)
    if lines and data.draw(st.booleans()):  # the last line without its line end
        text = text[:-1]
    path = tmp_path / "g.csv"
    path.write_text(text, encoding="utf-8")
    expected, error = _by_line(text, n, ceilings)
    with ColumnsReader(path) as reader:
        if error is not None:
            with pytest.raises(FormatError, match=re.escape(error)):
                list(reader.blocks(rows))
            return
        blocks = list(reader.blocks(rows))
    assert all(len(b[names[0]]) == rows for b in blocks[:-1])
    got = (
        np.column_stack([np.concatenate([b[c] for b in blocks]) for c in names]) if blocks else None
    )
    if expected.size == 0:
        assert got is None
    else:
        np.testing.assert_array_equal(got, expected)


def test_written_text_is_each_value_s_repr_across_the_writer_s_pieces(tmp_path):
    """Across the writer's pieces of rows, every value is written as its ``repr`` (the
    shortest text that reads back to the same float), in order, one row a line."""
    rng = np.random.default_rng(4)
    cols = {"time_s": np.arange(40_000) * 0.02, "p": rng.standard_normal(40_000) * 1e-3}
    cols["p"][[5, 20_000]] = [np.nan, -np.inf]
    path = write_columns_csv(tmp_path / "w.csv", cols)
    rows = zip(cols["time_s"].tolist(), cols["p"].tolist(), strict=True)
    expected = "# rows: 40000\ntime_s,p\n" + "".join(f"{a!r},{b!r}\n" for a, b in rows)
    assert path.read_text() == expected
