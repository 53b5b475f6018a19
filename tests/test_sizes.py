"""docs/development.md's table of what is longer than the guideline (functions over 80 lines,
modules over 600) is the code's: every such function and module is listed with its present
length, and nothing else is."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "python" / "texsense"
FUNCTION_LINES, MODULE_LINES = 80, 600


def _rust_functions(lines: list[str]) -> list[tuple[str, int]]:
    """(name, lines) of every ``fn`` with a body: from its signature to its closing brace."""
    out = []
    for i, line in enumerate(lines):
        m = re.match(r"^\s*(pub(\([a-z]+\))? )?(const )?(unsafe )?fn (\w+)", line)
        if not m:
            continue
        depth, started = 0, False
        for j in range(i, len(lines)):
            depth += lines[j].count("{") - lines[j].count("}")
            started = started or "{" in lines[j]
            if started and depth == 0:
                out.append((m.group(5), j - i + 1))
                break
            if not started and lines[j].rstrip().endswith(";"):
                break  # a declaration without a body (a trait's)
    return out


def measured() -> set[tuple[str, int]]:
    """("`path` `function`" or "`path`", lines) of everything over the guideline."""
    found: set[tuple[str, int]] = set()
    for p in sorted(PACKAGE.rglob("*.py")):
        rel, src = p.relative_to(PACKAGE).as_posix(), p.read_text(encoding="utf-8")
        if src.count("\n") > MODULE_LINES:
            found.add((f"`{rel}`", src.count("\n")))
        for node in ast.walk(ast.parse(src)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = node.end_lineno - node.lineno + 1  # type: ignore[operator]
                if n > FUNCTION_LINES:
                    found.add((f"`{rel}` `{node.name}`", n))
    for p in sorted((ROOT / "crates").rglob("*.rs")):
        rel, lines = p.relative_to(ROOT).as_posix(), p.read_text(encoding="utf-8").split("\n")
        if len(lines) - 1 > MODULE_LINES:
            found.add((f"`{rel}`", len(lines) - 1))
        for name, n in _rust_functions(lines):
            if n > FUNCTION_LINES:
                found.add((f"`{rel}` `{name}`", n))
    return found


def documented() -> set[tuple[str, int]]:
    text = (ROOT / "docs" / "development.md").read_text(encoding="utf-8")
    section = text.split("### Longer than the guideline", 1)[1].split("\n#", 1)[0]
    rows = re.findall(r"^\| (`[^|]+`) \| (\d+) \|", section, re.M)
    return {(where.strip(), int(n)) for where, n in rows}


def test_the_size_table_is_the_codes():
    code, docs = measured(), documented()
    missing = sorted(code - docs)
    stale = sorted(docs - code)
    rows = "\n".join(f"| {w} | {n} | ... |" for w, n in missing)
    assert not missing and not stale, (
        f"docs/development.md's size table: add or update\n{rows}\nremove {stale}"
    )


def test_the_measure_sees_a_long_rust_function():
    body = ["fn long() {", *["    x += 1;"] * 90, "}", "fn short() -> u8 { 1 }"]
    assert _rust_functions(body) == [("long", 92), ("short", 1)]
