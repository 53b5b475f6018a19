import json
import subprocess
import sys

import numpy as np
import pytest

import texsense
from texsense.cli import main


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "texsense.cli", *args], capture_output=True, text=True, check=False
    )


def test_info_iscan_json(shared_data, capsys):
    assert main(["info", str(shared_data / "vendor-formats" / "iscan_test.csv"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["rows"], info["cols"], info["frames"]) == (28, 28, 309)
    assert info["frame_period_s"] == pytest.approx(0.1)
    assert info["format"] == "tekscan" and info["unit"] == "count"


def test_info_pmd_tree_json(shared_data, capsys):
    assert main(["info", str(shared_data / "pmd" / "experiment-i"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["frames"] == 20024
    assert (info["rows"], info["cols"]) == (64, 32)
    assert info["subjects"] == 13
    assert info["postures"] == 17


def test_info_text_reads_well(shared_data, capsys):
    assert main(["info", str(shared_data / "vendor-formats" / "fscan_testL.asf")]) == 0
    out = capsys.readouterr().out
    assert "205  (0.032 s per frame" in out
    assert "pressure in N/cm2 (file: kPa)" in out
    assert "load        mean" in out


def test_info_of_a_processed_file_counts_its_repaired_readings(tmp_path, capsys):
    # `process` flags a repaired element invalid but keeps its estimate; info left it out of
    # the load (a processed night: max 428 N against the report's 494 N and the truth's 485 N)
    lay = texsense.Layout.grid(1, 4, pitch_cm=(2.0, 2.0))
    frames = np.array([[1.0, 1.0, 1.0, 1.0]], np.float32)
    valid = np.array([[True, True, False, True]])
    for stages, want in ((["convert", "repair:harmonic"], 16.0), (["convert"], 12.0)):
        rec = texsense.Recording(frames, [0.0], lay, valid=valid, meta={"stages": stages})
        rec.save(tmp_path / "p.h5")
        assert main(["info", str(tmp_path / "p.h5"), "--json"]) == 0
        info = json.loads(capsys.readouterr().out)
        assert info["load_N"]["max"] == pytest.approx(want)
        assert info["repairs_counted"] == (want == 16.0)
    assert main(["info", str(tmp_path / "p.h5")]) == 0
    assert "(repaired readings counted)" not in capsys.readouterr().out


def test_convert_to_every_writable_format(shared_data, tmp_path, capsys):
    src = shared_data / "vendor-formats" / "iscan_test.csv"
    original = texsense.load(src)
    for name in ("out.h5", "out.csv", "out.asf"):
        assert main(["convert", str(src), str(tmp_path / name)]) == 0
        back = texsense.load(tmp_path / name)
        np.testing.assert_array_equal(back.frames, original.frames)
        np.testing.assert_array_equal(back.times, original.times)
        assert back.layout.shape == (28, 28)
    assert "wrote" in capsys.readouterr().out


def test_convert_with_unit(shared_data, tmp_path):
    src = shared_data / "vendor-formats" / "fscan_testL.asf"
    assert main(["convert", str(src), str(tmp_path / "k.h5"), "--unit", "kPa"]) == 0
    assert texsense.load(tmp_path / "k.h5").unit == "kPa"


def test_plot_writes_a_png(shared_data, tmp_path):
    out = tmp_path / "map.png"
    assert (
        main(["plot", str(shared_data / "vendor-formats" / "pliance_test.asc"), "-o", str(out)])
        == 0
    )
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (
        main(
            [
                "plot",
                str(shared_data / "pmd" / "experiment-i" / "S3" / "2.txt"),
                "-o",
                str(out),
                "--frame",
                "5",
            ]
        )
        == 0
    )


def test_errors_exit_1_with_a_clear_message(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,e0\n0,x\n")
    proc = run_cli("info", str(bad))
    assert proc.returncode == 1
    assert "texsense info: error:" in proc.stderr and "bad.csv" in proc.stderr
    proc = run_cli("convert", str(bad), str(tmp_path / "out.xyz"))
    assert proc.returncode == 1 and "cannot tell the output format" in proc.stderr
    proc = run_cli("plot", str(tmp_path / "missing.h5"), "-o", str(tmp_path / "x.png"))
    assert proc.returncode == 1 and "no such file" in proc.stderr


def test_bad_usage_exits_2_and_help_reads_well():
    assert run_cli().returncode == 2
    assert run_cli("info").returncode == 2
    proc = run_cli("--help")
    assert proc.returncode == 0
    for command in ("info", "convert", "plot"):
        assert command in proc.stdout
