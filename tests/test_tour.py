"""Every console line of the README and of docs/*.md runs as written (tests/tour.py)."""

import pytest

from conftest import ROOT
from tour import commands, run_page

PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
PAGES = [p for p in PAGES if commands(p)]


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_page_runs_as_written(page, tmp_path, shared_data, capsys):
    outcome = run_page(page, tmp_path, shared_data.parent)
    with capsys.disabled():
        for text, why in outcome.skipped:
            print(f"\n  {page.name}: skipped (needs {why}): {text}")
    assert not outcome.failures, "\n\n".join(outcome.failures)
    assert outcome.ran
