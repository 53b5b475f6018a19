"""The simulator is the ground truth the compensation is graded against, so it must not be
built from it: texsense.sim imports only the data model, the sensor design rules and the
compiled spacer laws — never calibration, hysteresis, drift, repair or the pipeline."""

import ast
from pathlib import Path

import texsense.sim

ALLOWED = {
    "texsense",  # the package root re-exports the data model
    "texsense._core",
    "texsense._progress",
    "texsense.exceptions",
    "texsense.data.layout",
    "texsense.data.recording",
    "texsense.data.units",
    # the virtual device (sim/device.py) speaks the serial wire format and records its truth:
    # formats, not models
    "texsense.data.protocol",
    "texsense.io.hdf5",
}


def test_sim_imports_only_the_data_model_and_sensor():
    root = Path(texsense.sim.__file__).parent
    seen = {}
    for path in sorted(root.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            for name in names:
                if name.startswith("texsense"):
                    seen.setdefault(name, set()).add(path.name)
    bad = {
        name: files
        for name, files in seen.items()
        if name not in ALLOWED and not name.startswith(("texsense.sim", "texsense.sensor"))
    }
    assert not bad, f"texsense.sim imports {bad}"
    assert any(name.startswith("texsense.sim.") for name in seen)  # the walk saw imports
