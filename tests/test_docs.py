"""The python examples in docs/*.md run as written (from the repository root)."""

import re
from pathlib import Path

import pytest

from conftest import ROOT

BLOCK = re.compile(r"```python\n(.*?)```", re.DOTALL)
PAGES = sorted((ROOT / "docs").glob("*.md"))


def examples():
    for page in PAGES:
        for k, code in enumerate(BLOCK.findall(page.read_text())):
            yield pytest.param(page, code, id=f"{page.name}#{k}")


@pytest.mark.parametrize(("page", "code"), list(examples()))
def test_example_runs(page: Path, code: str, monkeypatch, shared_data, capsys):
    monkeypatch.chdir(ROOT)
    exec(compile(code, str(page), "exec"), {"__name__": "__docs__"})
    assert capsys.readouterr().out  # every example prints something to look at
