"""Fault cases of texsense record: outputs that exist, outputs onto the input, missing
ports."""

from faults.conftest import assert_clear_error, run_cli


def test_record_never_writes_over_a_file_or_its_input(tmp_path, fault_row):
    (tmp_path / "taken.h5").write_bytes(b"precious")
    rc, _, err = run_cli("record", "--source", "virtual", "-o", "taken.h5", "--frames", "1",
                         cwd=tmp_path)  # fmt: skip
    assert_clear_error(rc, err, "taken.h5", "never written over")
    assert (tmp_path / "taken.h5").read_bytes() == b"precious"
    fault_row("record", "-o names an existing file", "data kept")
    rc, _, err = run_cli("record", "--source", "replay:taken.h5", "-o", "taken.h5", cwd=tmp_path)
    assert_clear_error(rc, err, "taken.h5")
    fault_row("record", "-o is the replayed input", "clear error")


def test_record_from_a_missing_serial_port_without_grid_is_one_line(tmp_path, fault_row):
    rc, _, err = run_cli("record", "--source", "serial:/dev/ttyNOPE9", "-o", "x.h5",
                         "--frames", "1", cwd=tmp_path)  # fmt: skip
    assert_clear_error(rc, err, "serial:/dev/ttyNOPE9", "cannot open")
    assert not (tmp_path / "x.h5").exists()
    fault_row("record", "a serial port that is missing (no --grid)", "clear error")
