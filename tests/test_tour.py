"""Every console line of the README and of docs/*.md runs as written (tests/tour.py).

The pages run two at a time, once per session (the selected pages only); each test reports
its page.
"""

import pytest

from conftest import ROOT
from tour import commands, run_pages

PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
PAGES = [p for p in PAGES if commands(p)]  # the README first: the longest


@pytest.fixture(scope="session")
def outcomes(request, shared_data, tmp_path_factory):
    selected = [
        item.callspec.params["page"]
        for item in request.session.items
        if getattr(item, "originalname", None) == "test_page_runs_as_written"
    ]
    return run_pages(selected, tmp_path_factory.mktemp("tour"), shared_data.parent, jobs=2)


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_page_runs_as_written(page, outcomes, capsys):
    outcome = outcomes[page]
    with capsys.disabled():
        print(f"\n  {page.name}: {len(outcome.ran)} commands in {outcome.seconds:.1f} s")
        for text, why in outcome.skipped:
            print(f"  {page.name}: skipped (needs {why}): {text}")
    assert not outcome.failures, "\n\n".join(outcome.failures)
    assert outcome.ran
