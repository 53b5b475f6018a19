import pytest

from texsense.exceptions import FormatError
from texsense.io import load, sniff_format


@pytest.mark.parametrize(
    ("relative", "fmt"),
    [
        ("vendor-formats/iscan_test.csv", "tekscan"),
        ("vendor-formats/fscan_testL.asf", "tekscan"),
        ("vendor-formats/xsensor_data.csv", "xsensor"),
        ("vendor-formats/pliance_test.asc", "pliance"),
        ("pmd/experiment-i", "pmd"),
        ("pmd/experiment-i/S4", "pmd"),
        ("pmd/experiment-i/S4/12.txt", "pmd"),
    ],
)
def test_sniffs_real_files_by_content(shared_data, relative, fmt):
    assert sniff_format(shared_data / relative) == fmt


def test_mislabelled_extension_is_read_by_content(shared_data, tmp_path):
    # an XSENSOR export saved with a .txt extension is still an XSENSOR export
    src = shared_data / "vendor-formats" / "xsensor_data.csv"
    dst = tmp_path / "renamed.txt"
    dst.write_bytes(src.read_bytes())
    assert load(dst).meta["format"] == "xsensor-csv"


def test_unknown_and_binary_files(tmp_path):
    odd = tmp_path / "notes.txt"
    odd.write_text("hello world\n")
    with pytest.raises(FormatError, match="unknown format; texsense reads"):
        load(odd)
    fsx = tmp_path / "movie.fsx"
    fsx.write_bytes(b"\x00\x01binary")
    with pytest.raises(FormatError, match="Tekscan binary movie"):
        load(fsx)
    with pytest.raises(FormatError, match="no such file"):
        load(tmp_path / "absent.csv")
    binary = tmp_path / "bin.csv"
    binary.write_bytes(b"DATA_TYPE\x00\x00")
    with pytest.raises(FormatError, match="binary file"):
        load(binary, format="tekscan")
