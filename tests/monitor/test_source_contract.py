"""One contract for every live source (the sources of the registry, texsense.monitor.sources
SOURCES, and the station's fed source): a layout, a quantity the monitor can use with its
unit, an ``info()`` the status page shows, frames of the layout's size in order, and a
``close()`` that can be called twice. A source added to the registry without a case here fails
``test_every_source_has_a_case``."""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from texsense import Layout, Recording
from texsense.data import units
from texsense.data.protocol import Frame, format_serial_line
from texsense.io import save
from texsense.monitor.sources import (
    Source,
    SourceOptions,
    available_sources,
    open_source,
    source_help,
)


def check_source(source: Source, n_frames: int) -> list[Frame]:
    """The contract; returns the first ``n_frames`` frames."""
    n = source.layout.n_elements
    assert n > 0
    assert source.quantity in ("capacitance", "pressure"), source.quantity
    assert units.quantity_of(source.unit) == source.quantity, (source.quantity, source.unit)
    info = source.info()
    assert {"name", "quantity", "unit", "elements", "errors", "problem"} <= set(info)
    assert info["elements"] == n and info["errors"] == 0
    frames: list[Frame] = []

    async def take() -> None:
        async for f in source.frames():
            frames.append(f)
            if len(frames) == n_frames:
                return

    if n_frames:
        asyncio.run(asyncio.wait_for(take(), 120))
    for a, b in itertools.pairwise(frames):
        assert b.seq > a.seq and b.t >= a.t
    for f in frames:
        assert f.values.shape == (n,) and f.element_times.shape == (n,)
        assert f.unit == source.unit
    source.close()
    source.close()
    return frames


def _iio_tree(tmp: Path) -> str:
    dev = tmp / "iio:device0"
    dev.mkdir()
    for c in range(4):
        (dev / f"in_capacitance{c}_raw").write_text(f"{1_000_000 * (c + 1)}\n")
        (dev / f"in_capacitance{c}_scale").write_text("0.000000488\n")
        (dev / f"in_capacitance{c}_offset").write_text("0\n")
    return f"iio:{dev}"


def _replay_file(tmp: Path) -> str:
    rec = Recording(np.arange(12.0).reshape(6, 2) + 1, np.arange(6) * 0.5, Layout.grid(1, 2),
                    "pressure", "N/cm2")  # fmt: skip
    return f"replay:{save(rec, tmp / 'r.h5')}"


def _serial_loop(source: Source) -> None:
    lines = "".join(format_serial_line(k, k * 100, 100, [5.0, 6.0]) + "\n" for k in range(3))
    source._dev.write(lines.encode())  # type: ignore[attr-defined]


#: scheme -> (the --source spec in a folder, options, frames to read, what to do once open)
Case = tuple[Callable[[Path], str], SourceOptions, int, Callable[[Source], None] | None]
CASES: dict[str, Case] = {
    "replay": (_replay_file, SourceOptions(speed=0), 3, None),
    "serial": (lambda tmp: "serial:loop://", SourceOptions(grid=Layout.grid(1, 2)), 2,
               _serial_loop),
    "iio": (_iio_tree, SourceOptions(grid=Layout.grid(2, 2)), 2, None),
    "mqtt": (lambda tmp: "mqtt:127.0.0.1:1", SourceOptions(grid=Layout.grid(2, 2)), 0, None),
    "virtual": (lambda tmp: "virtual", SourceOptions(speed=0), 2, None),
    "virtual-bed": (lambda tmp: "virtual-bed", SourceOptions(speed=0), 1, None),
}  # fmt: skip


def test_every_source_has_a_case():
    missing = sorted(set(available_sources()) - set(CASES))
    assert not missing, f"sources without a contract case here: {missing}"
    assert set(CASES) == set(available_sources())


@pytest.mark.parametrize("scheme", list(CASES))
def test_source_contract(scheme, tmp_path):
    spec, options, n_frames, after_open = CASES[scheme]
    source = open_source(spec(tmp_path), options)
    assert source.scheme == scheme and type(source).summary
    if after_open is not None:
        after_open(source)
    check_source(source, n_frames)


def test_the_stations_fed_source_keeps_the_contract():
    from texsense.station.ward import MatConfig, _FedSource

    check_source(_FedSource(MatConfig("m1", Layout.grid(2, 3))), 0)


def test_unknown_and_malformed_specs_name_what_is_known():
    with pytest.raises(Exception, match="known: replay:FILE") as e:
        open_source("bluetooth:aa")
    assert source_help() in str(e.value)
    with pytest.raises(Exception, match="needs --grid"):
        open_source("iio:/nonexistent", SourceOptions())
    with pytest.raises(Exception, match="the port must be a number"):
        open_source("mqtt:host:x", SourceOptions(grid=Layout.grid(1, 1)))
    with pytest.raises(Exception, match="takes nothing after the colon"):
        open_source("virtual-bed:2")
