"""texsense on a mat's own microcontroller (docs/embedded.md): the README's calibration
exported with ``texsense export mcu``, run frame by frame through the C ABI by a C program
built with gcc, on the host and on an emulated Cortex-M4 (QEMU mps2-an386), against the
Python pipeline; the fault cases; the header is what cbindgen makes of the crate.

The builds (tests/mcu/build.py) start in the background when this module is collected and
are cached in target/mcu/ (``core`` and ``compiler_builtins`` once per compiler); under
``pytest -n N`` the module's tests run in one worker (one build, no race on the cache), which
builds at its first test."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from texsense.cli import main
from texsense.compensation.drift import DriftModel, log_kernel
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import Drift, StageChain, load_chain
from texsense.sim.mat import VirtualMat
from texsense.sim.seated import SEAT_FAILURES

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "mcu"))
import build  # noqa: E402

pytestmark = pytest.mark.xdist_group("mcu")

#: float32 against float64, frame by frame over the whole session: |C - Python| <=
#: RTOL |Python| + ATOL (N/cm²); docs/embedded.md "Accuracy" shows the measured errors
RTOL, ATOL = 1e-5, 2e-5


def write_frames(path: Path, cap: np.ndarray, valid: np.ndarray, times: np.ndarray) -> None:
    """frames.bin of tests/mcu/test_mat.c: per frame dt (f32), readings (f32), validity."""
    t, n = cap.shape
    dt = np.diff(times, prepend=times[0]).astype("<f4")
    with path.open("wb") as f:
        f.write(b"TXSNFRM1" + np.array([n, t], "<u4").tobytes())
        for k in range(t):
            f.write(dt[k].tobytes() + cap[k].astype("<f4").tobytes())
            f.write(valid[k].astype(np.uint8).tobytes())


def read_out(path: Path, t: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """out.bin: per frame values (f32) and codes."""
    raw = np.frombuffer(path.read_bytes(), np.uint8)
    assert raw.size == t * n * 5, "out.bin holds every frame"
    rows = raw.reshape(t, 5 * n)
    values = rows[:, : 4 * n].copy().view("<f4").reshape(t, n)
    return values, rows[:, 4 * n :]


@pytest.fixture(scope="module")
def mats(tmp_path_factory):
    """The README's calibration of the virtual seat (its device's mat: seed 0, unloaded and
    under 1 N/cm², the textile-3mm test-machine record; ``texsense calibrate mat``: detect,
    convert, hysteresis), exported with ``texsense export mcu``; the same with a drift stage
    on the rest clock with a second clock on time and a level power (idw8 repair), and with
    a QLV drift (last-value repair); and a session on the same mat with the thesis's
    failures, a load that comes and goes, and frames of NaN, zero and flagged readings.
    Per variant: its folder (mat.bin, frames.bin) and the Python pipeline's values and
    codes."""
    root = tmp_path_factory.mktemp("mcu")
    mat = VirtualMat.seat(seed=0)
    n = mat.layout.n_elements
    ft = mat.cdc.frame_time_s(n)
    mat.scan(np.arange(5) * ft, np.zeros((5, n))).capacitance.save(root / "base.h5")
    mat.scan((5 + np.arange(5)) * ft, np.ones((5, n))).capacitance.save(root / "uniform.h5")
    cli = [
        ["simulate", "calibration", "--spacer", "textile-3mm", "--csv", f"{root}/spacer.csv"],
        ["calibrate", "mat", "--material", f"{root}/spacer.csv", "--baseline",
         f"{root}/base.h5", "--uniform", f"{root}/uniform.h5", "--pressure", "1",
         "--thickness-mm", "3", "-o", f"{root}/mat.json"],
    ]  # fmt: skip
    for argv in cli:
        assert main(argv) == 0, argv
    readme = load_chain(root / "mat.json")
    model = readme["hysteresis"].model_
    drift = DriftModel(-0.025, log_kernel(), "log", rest_rate=0.1, gamma_time=-0.01, exponent=1.5)
    qlv = DriftModel(-0.025, log_kernel(), level="backbone", backbone=model.backbone_curve())
    chains = {
        "readme": (readme, "neighbour-mean"),
        "drift": (StageChain([*readme.stages, Drift.of(drift)]), "idw8"),
        "qlv": (StageChain([*readme.stages, Drift.of(qlv)]), "last-value"),
    }
    session = VirtualMat.seat(seed=0, failures=SEAT_FAILURES)
    t = 400
    times = np.arange(t) * ft * 4
    xy = session.layout.xy_cm
    on = (np.sin(times / 9.0) > -0.4)[:, None]
    load = on * (0.3 + 2.4 * np.exp(-np.sum((xy - xy.mean(0)) ** 2, axis=1) / 70.0))[None, :]
    load = load * (1 + 0.25 * np.sin(times / 2.3))[:, None]
    rec = session.scan(times, load).capacitance
    cap = np.asarray(rec.frames, np.float32).astype(np.float64)
    valid = rec.valid & (np.random.default_rng(3).random(cap.shape) > 0.01)
    cap[150], cap[151], valid[152] = np.nan, 0.0, False  # a frame of NaN, of 0, all flagged
    out = {}
    for name, (chain, repair) in chains.items():
        folder = root / name
        folder.mkdir()
        chain.save(folder / "mat.json")
        argv = ["export", "mcu", f"{folder}/mat.json", "-o", f"{folder}/mat.bin"]
        assert main([*argv, "--repair", repair]) == 0
        write_frames(folder / "frames.bin", cap, valid, rec.times)
        # the microcontroller's memory of turning points (the default of the export)
        pipe = Pipeline(chain, rec.layout, repair=repair, capacity=16)
        expected, ok, codes = pipe.process(cap, rec.times, valid)
        out[name] = folder, expected, codes, (~ok).mean()
    return out


VARIANTS = ["readme", "drift", "qlv"]


def compare(folder: Path, expected: np.ndarray, codes: np.ndarray, output: str) -> np.ndarray:
    """The C program's run against the Python pipeline; returns the relative errors."""
    assert "ALL CHECKS PASSED" in output and output.rstrip().endswith("exit 0"), output
    values, got_codes = read_out(folder / "out.bin", *expected.shape)
    np.testing.assert_array_equal(got_codes, codes)
    np.testing.assert_array_equal(np.isnan(values), np.isnan(expected))
    fin = np.isfinite(expected)
    err = np.abs(values[fin] - expected[fin])
    bound = RTOL * np.abs(expected[fin]) + ATOL
    worst = int(np.argmax(err - bound))
    rel = err / np.maximum(np.abs(expected[fin]), 1e-3)
    assert np.all(err <= bound), (
        f"float32 differs by {err[worst]:.3g} at {expected[fin][worst]:.6g} (bound "
        f"{bound[worst]:.3g}); max relative {rel.max():.3g}"
    )
    return rel


FAULTS = {
    "damaged blob": "TS_ERR_CHECKSUM",
    "other version": "TS_ERR_VERSION",
    "cut short": "TS_ERR_LENGTH",
    "not a blob": "TS_ERR_MAGIC",
    "misaligned blob": "TS_ERR_ALIGN",
    "wrong element count": "TS_ERR_ELEMENTS",
    "memory too small": "TS_ERR_MEMORY",
    "not initialised": "TS_ERR_STATE",
    "negative time step": "TS_ERR_TIME",
    "NaN readings": "TS_OK",
    "NaN readings are shorts or breaks": "TS_OK",
    "zero readings are shorts or breaks": "TS_OK",
}


def check_faults(output: str) -> None:
    for what, status in FAULTS.items():
        assert f"check {what}: {status} (ok)" in output, (what, output)


def built(kind: str) -> build.Built:
    """The build started when the module was collected (conftest), or now."""
    from conftest import MCU_BUILDS

    future = MCU_BUILDS.get(kind)
    try:
        return future.result() if future is not None else build.build(kind)
    except build.MissingError as e:
        pytest.skip(f"missing {e}: scripts/test.sh installs it with apt-get when run as root")


@pytest.mark.parametrize("variant", VARIANTS)
def test_a_calibration_runs_in_c_on_the_host_as_in_python(mats, variant):
    folder, expected, codes, failed = mats[variant]
    out = build.run_program(built("host"), folder, timeout=120)
    rel = compare(folder, expected, codes, out)
    check_faults(out)
    assert failed > 0.02 and rel.size > 0.9 * expected.size * (1 - failed)


@pytest.mark.parametrize("variant", VARIANTS)
def test_a_calibration_runs_on_an_emulated_cortex_m4_as_in_python(mats, variant):
    folder, expected, codes, _ = mats[variant]
    program = built("arm")
    try:
        build.qemu()
    except build.MissingError as e:
        pytest.skip(f"missing {e}: scripts/test.sh installs it with apt-get when run as root")
    out = build.run_program(program, folder, timeout=600)
    compare(folder, expected, codes, out)
    check_faults(out)


def test_the_header_is_what_cbindgen_makes_of_the_crate(tmp_path):
    cbindgen = shutil.which("cbindgen")
    if cbindgen is None:
        pytest.skip("missing cbindgen (Debian package cbindgen)")
    made = tmp_path / "texsense.h"
    subprocess.run(
        [cbindgen, "--config", "crates/mcu/cbindgen.toml", "--crate", "texsense-mcu", "-o",
         str(made), "--quiet"],
        cwd=ROOT, check=True,
    )  # fmt: skip
    committed = ROOT / "crates" / "mcu" / "include" / "texsense.h"
    assert made.read_text() == committed.read_text(), (
        "crates/mcu/include/texsense.h is behind crates/mcu/src/lib.rs: run "
        "cbindgen --config crates/mcu/cbindgen.toml --crate texsense-mcu "
        "-o crates/mcu/include/texsense.h"
    )
