"""Fault cases of texsense calibrate mat and calibrate wizard: wrong material, wrong units,
swapped or unusable recordings, bad parameters; each one clear line, nothing written."""

import numpy as np
import pytest

from faults.conftest import assert_clear_error, run_cli
from texsense.io import save
from texsense.sim import protocols
from texsense.sim.mat import VirtualMat


@pytest.fixture(scope="module")
def mat_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cal")
    mat = VirtualMat.seat(seed=1)
    n = mat.layout.n_elements
    ft = mat.cdc.frame_time_s(n)
    save(mat.scan(np.arange(8) * ft, np.zeros((8, n))).capacitance, folder / "zero.h5")
    save(mat.scan((9 + np.arange(8)) * ft, np.ones((8, n))).capacitance, folder / "one.h5")
    save(mat.scan((18 + np.arange(2)) * ft, np.ones((2, n))).capacitance, folder / "short.h5")
    m6 = protocols.run_protocol("calibration", "textile-6mm", seed=2, sample_hz=None)
    lines = ["compression_mm,capacitance_pF,pressure_ncm2"] + [
        f"{e},{c},{p}"
        for e, c, p in zip(
            m6.labels["compression_mm"], m6.frames[:, 0], m6.labels["pressure_ncm2"], strict=True
        )
    ]
    (folder / "m6.csv").write_text("\n".join(lines) + "\n")
    return folder


def _calibrate(folder, *args):
    return run_cli("calibrate", "mat", "--baseline", "zero.h5", "--uniform", "one.h5",
                   "-o", "mat.json", *args, cwd=folder)  # fmt: skip


CASES = [
    (
        ("--material", "m6.csv", "--thickness-mm", "3", "--pressure", "1"),
        ("m6.csv", "thicker"),
        "a record of a 6 mm spacer with --thickness-mm 3",
    ),
    (
        ("--material", "m6.csv", "--pressure", "1"),
        ("--thickness-mm", "about 5."),
        "a record without --thickness-mm",
    ),
    (
        ("--material", "textile-3mm", "--pressure", "75"),
        ("75 N/cm²", "mmHg"),
        "--pressure 75 (mmHg meant, no unit)",
    ),
    (
        ("--material", "textile-3mm", "--pressure", "1 psi!"),
        ("pressure", "1 psi!"),
        "--pressure with an unknown unit",
    ),
    (
        ("--material", "felt-2mm", "--pressure", "1"),
        ("felt-2mm", "presets"),
        "an unknown spacer preset",
    ),
    (
        ("--material", "textile-3mm", "--thickness-mm", "6", "--pressure", "1"),
        ("textile-3mm is 3 mm",),
        "--thickness-mm against a preset's own",
    ),
]


@pytest.mark.parametrize("args, names, case", CASES, ids=[c[2] for c in CASES])
def test_calibrate_mat_refuses_with_one_line(mat_files, fault_row, args, names, case):
    rc, _, err = _calibrate(mat_files, *args)
    assert_clear_error(rc, err, *names)
    assert not (mat_files / "mat.json").exists()
    fault_row("calibrate", case, "clear error")


def test_swapped_and_short_recordings_are_refused(mat_files, fault_row):
    rc, _, err = run_cli("calibrate", "mat", "--baseline", "one.h5", "--uniform", "zero.h5",
                         "--material", "textile-3mm", "--pressure", "1", "-o", "mat.json",
                         cwd=mat_files)  # fmt: skip
    assert_clear_error(rc, err, "swapped")
    fault_row("calibrate", "zero and uniform recordings swapped", "clear error")
    rc, _, err = run_cli("calibrate", "mat", "--baseline", "zero.h5", "--uniform", "short.h5",
                         "--material", "textile-3mm", "--pressure", "1", "-o", "mat.json",
                         cwd=mat_files)  # fmt: skip
    assert_clear_error(rc, err, "short.h5", "2 frames")
    assert not (mat_files / "mat.json").exists()
    fault_row("calibrate", "a uniform recording of 2 frames", "clear error")


def test_wizard_parameters_and_a_missing_port(tmp_path, fault_row):
    rc, _, err = run_cli("calibrate", "wizard", "--source", "serial:/dev/ttyNOPE7", "-o",
                         "m.json", "--yes", cwd=tmp_path)  # fmt: skip
    assert_clear_error(rc, err, "serial:/dev/ttyNOPE7", "cannot open")
    fault_row("calibrate wizard", "a serial port that is missing", "clear error")
    rc, _, err = run_cli("calibrate", "wizard", "--source", "virtual", "-o", "m.json",
                         "--pressure", "ten", cwd=tmp_path)  # fmt: skip
    assert_clear_error(rc, err, "ten")
    fault_row("calibrate wizard", "--pressure that is not a number", "clear error")
    assert not list(tmp_path.iterdir())


def test_a_failed_write_keeps_the_previous_calibration(mat_files, fault_row):
    """The disk fills (a file-size limit of 4 KiB) while the chain is written: the previous
    mat.json stays as it was, no temporary file is left, one line says why."""
    import resource

    previous = mat_files / "mat.json"
    previous.write_text('{"the": "previous calibration"}')
    limit = lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))  # noqa: E731
    args = ("calibrate", "mat", "--baseline", "zero.h5", "--uniform", "one.h5", "--material",
            "textile-3mm", "--pressure", "1", "-o", "mat.json")  # fmt: skip
    # without --replace a calibration is not written over at all (issue 33), with it the
    # failed write leaves the previous one
    rc, _, err = run_cli(*args, cwd=mat_files)
    assert_clear_error(rc, err, "mat.json", "--replace")
    rc, _, err = run_cli(*args, "--replace", cwd=mat_files, preexec=limit)
    assert_clear_error(rc, err, "mat.json", "File too large")
    assert previous.read_text() == '{"the": "previous calibration"}'
    assert sorted(p.name for p in mat_files.iterdir() if p.name.startswith(".")) == []
    previous.unlink()
    fault_row("calibrate", "calibrate mat with a file-size limit of 4 KiB", "data kept")
