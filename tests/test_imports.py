"""The import structure of python/texsense (issue 24, item 4): no cycles, counting the imports
inside functions too; an import inside a function only where it is justified (it brings a
heavy optional library that the module does not otherwise need, or it is the one late-bound
façade); the command line imports only what the command that runs needs."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "python" / "texsense"

#: Libraries that take long to import or are needed by one feature only: a module imports
#: them inside the function that needs them (or imports a texsense module that does).
HEAVY = {
    "sklearn", "scipy", "matplotlib", "h5py", "dask", "distributed", "fastapi", "uvicorn",
    "starlette", "websockets", "paho", "serial", "psycopg", "joblib", "playwright",
}  # fmt: skip

#: Standard modules that exist on some platforms only (POSIX terminals and resources).
PLATFORM = {"resource", "fcntl", "termios", "pty", "tty"}

#: Imports inside functions that close what would be a cycle, each with its reason.
LATE_BOUND = {
    (
        "texsense.data.recording",
        "texsense.io",
    ): "Recording.save is a façade over texsense.io, whose "
    "readers build recordings (so texsense.io depends on texsense.data.recording)",
    ("texsense.io", "texsense.io.apart"): "open_recording(apart=True) hands the read to "
    "texsense.io.apart, whose child process runs texsense.io.load",
    ("texsense.calibration", "texsense.compensation.conversion"): "the names of the eq. 2.1 "
    "module that was texsense.calibration, found there for one release (with a warning)",
}


@dataclass
class Module:
    name: str
    path: Path
    top: set[str] = field(default_factory=set)  # modules imported at module level
    inside: list[tuple[str, int]] = field(default_factory=list)  # (module, line) in functions


def _names() -> dict[str, Path]:
    mods = {"texsense._core": PACKAGE / "_core.pyi"}  # the compiled core: a leaf
    for p in PACKAGE.rglob("*.py"):
        parts = list(p.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = p
    return mods


@cache
def modules() -> dict[str, Module]:
    """Every module with what it imports at module level and inside functions (imports
    under ``if TYPE_CHECKING:`` are for the type checker only and do not run)."""
    names = _names()
    out = {}
    for name, path in names.items():
        if path.suffix == ".pyi":
            out[name] = Module(name, path)
            continue
        mod = Module(name, path)
        is_pkg = path.name == "__init__.py"

        def target(node: ast.AST, module: str, alias: str | None) -> str:
            level = getattr(node, "level", 0)
            if level:
                base = name.split(".") if is_pkg else name.split(".")[:-1]  # noqa: B023
                module = ".".join(base[: len(base) - level + 1] + ([module] if module else []))
            full = f"{module}.{alias}" if alias else module
            return full if full in names else module

        def visit(node: ast.AST, depth: int) -> None:
            if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
                return
            found: list[str] = []
            if isinstance(node, ast.Import):
                found = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                found = [target(node, node.module or "", a.name) for a in node.names]
            elif (
                isinstance(node, ast.Call)
                and ast.unparse(node.func) == "importlib.import_module"
                and node.args
                and isinstance(node.args[0], ast.Constant)
            ):
                found = [node.args[0].value]  # a late-bound import by a literal name
            for t in found:
                if depth:
                    mod.inside.append((t, node.lineno))  # noqa: B023
                else:
                    mod.top.add(t)  # noqa: B023
            inner = depth + isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
            for child in ast.iter_child_nodes(node):
                visit(child, inner)

        visit(ast.parse(path.read_text(encoding="utf-8")), 0)
        out[name] = mod
    return out


def _internal(target: str) -> str | None:
    """The texsense module an import names (its longest known prefix)."""
    names = modules()
    parts = target.split(".")
    while parts and ".".join(parts) not in names:
        parts.pop()
    return ".".join(parts) if parts and parts[0] == "texsense" else None


def _runs(importer: str, target: str) -> list[str]:
    """What importing ``target`` from ``importer`` runs: the module and its packages' inits
    (those the importer is not inside of already)."""
    parts = target.split(".")
    chain = [".".join(parts[: k + 1]) for k in range(1, len(parts))]
    return [m for m in chain if m == target or not importer.startswith(m + ".")]


@cache
def heavy(name: str) -> frozenset[str]:
    """The modules of heavy libraries that importing module ``name`` loads (module level,
    transitively), e.g. ``scipy.sparse``."""
    seen: set[str] = set()
    found: set[str] = set()
    todo = [name]
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.add(m)
        for t in modules()[m].top:
            inner = _internal(t)
            if inner is None:
                if t.split(".")[0] in HEAVY:
                    found.add(t)
            else:
                todo.extend(_runs(m, inner))
    return frozenset(found)


def graph() -> dict[str, set[str]]:
    """Module -> the modules it imports, at module level or inside functions."""
    g: dict[str, set[str]] = {name: set() for name in modules()}
    for name, mod in modules().items():
        for t in [*mod.top, *(t for t, _ in mod.inside)]:
            inner = _internal(t)
            if inner is not None and (name, inner) not in LATE_BOUND:
                g[name].update(m for m in _runs(name, inner) if m != name)
    return g


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in g[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(g)))
    for v in g:
        if v not in index:
            visit(v)
    return out


def unjustified() -> list[str]:
    """The imports inside functions that have no reason to be there."""
    bad = []
    for name, mod in modules().items():
        own = heavy(name)
        for t, line in mod.inside:
            inner = _internal(t)
            where = f"{mod.path.relative_to(PACKAGE.parent)}:{line} imports {t}"
            if inner is None:
                top = t.split(".")[0]
                if not ((top in HEAVY and t not in own) or top in PLATFORM):
                    bad.append(where)
            elif (name, inner) not in LATE_BOUND and not (heavy(inner) - own):
                bad.append(where)
    return bad


def test_the_analysis_sees_what_it_should():
    mods = modules()
    assert "texsense.compensation.stages.chain" in mods and "texsense.io" in mods
    assert ("texsense.io", 0) != ("", 0)
    assert any(t == "texsense.io" for t, _ in mods["texsense.data.recording"].inside)
    assert "h5py" in heavy("texsense.io") and not heavy("texsense.data.units")
    assert not heavy("texsense.compensation.repair")  # scipy only where the harmonic repair solves
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(g) == [["a", "b", "c"]]


def test_no_import_cycles_counting_the_imports_inside_functions():
    assert cycles(graph()) == []


def test_the_late_bound_imports_are_inside_functions():
    for importer, target in LATE_BOUND:
        mod = modules()[importer]
        assert target in {t for t, _ in mod.inside}, f"{importer} no longer imports {target}"
        assert target not in mod.top, f"{importer} imports {target} at module level"


def test_imports_inside_functions_are_justified():
    """An import inside a function brings a heavy optional library (HEAVY) the module does
    not load otherwise, is a platform's module, or is a late-bound façade (LATE_BOUND)."""
    assert unjustified() == []


@pytest.mark.parametrize(
    "argv",
    [["--help"], ["--version"], ["info", "--help"], ["process", "--help"], ["station", "--help"]],
)
def test_the_command_line_loads_only_what_the_command_needs(argv):
    code = (
        "import json, sys\n"
        "from texsense.cli import main\n"
        "try:\n"
        f"    main({argv!r})\n"
        "except SystemExit:\n"
        "    pass\n"
        "heavy = sorted(m for m in {'sklearn', 'scipy', 'h5py', 'matplotlib', 'dask'} "
        "if m in sys.modules)\n"
        "cmds = sorted(m for m in sys.modules if m.startswith('texsense.commands.') "
        "and not m.startswith('texsense.commands._'))\n"  # shared option helpers are fine
        "print('LOADED', json.dumps([heavy, cmds, 'numpy' in sys.modules]))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120
    ).stdout
    line = next(x for x in out.splitlines() if x.startswith("LOADED"))
    heavy_loaded, commands, numpy_loaded = json.loads(line[len("LOADED ") :])
    if argv[0] == "info":  # the info command's module (and the readers it needs) only
        assert commands == ["texsense.commands.info"] and "sklearn" not in heavy_loaded, line
    elif argv[0] == "process":  # the posture classifiers (scikit-learn) are not needed
        assert "texsense.commands.pipeline" in commands and "sklearn" not in heavy_loaded, line
    elif argv[0] == "station":  # scikit-learn only for a bed's posture model (every member
        assert "sklearn" not in heavy_loaded, line  # of a group starts faster)
    else:
        assert heavy_loaded == [] and commands == [] and not numpy_loaded, line


def test_a_monitor_of_a_recording_starts_without_the_classifiers(tmp_path, shared_data):
    """A monitor with no posture model (a replay, a serial mat) loads neither scikit-learn
    (with scipy.stats: ~2 CPU-s of import) nor scipy.ndimage: each start of a monitor pays
    only for what it uses."""
    asf = shared_data / "vendor-formats" / "fscan_testL.asf"
    code = (
        "import json, sys\n"
        "from texsense.cli import build_parser\n"
        "from texsense.commands.monitor import build_monitor\n"
        "import texsense.monitor.server\n"
        "args = build_parser(['monitor']).parse_args(\n"
        f"    ['monitor', '--source', 'replay:{asf}', '--db', 'm.sqlite'])\n"
        "m = build_monitor(args)\n"
        "heavy = sorted(x for x in ('sklearn', 'scipy.stats', 'scipy.ndimage') "
        "if x in sys.modules)\n"
        "print('LOADED', json.dumps([heavy, m.source.name]))\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=tmp_path
    )
    line = next((x for x in run.stdout.splitlines() if x.startswith("LOADED")), run.stderr)
    heavy_loaded, name = json.loads(line[len("LOADED ") :])
    assert "fscan_testL" in name and heavy_loaded == [], line


#: The layers of the tree, lowest first (docs/development.md, texsense/__init__.py): a module
#: imports only from its own group and from groups of lower rank; groups of one rank do not
#: import each other (the compensation never uses the simulator that grades it, nor the other
#: way round).
LAYERS = [
    (0, "base", ("texsense", "texsense._core", "texsense.exceptions", "texsense._progress",
                 "texsense._compat")),
    (1, "data", ("texsense.data", "texsense.io")),
    (2, "compensation", ("texsense.compensation",)),
    (2, "physics", ("texsense.sensor", "texsense.sim")),
    (3, "calibration", ("texsense.calibration",)),
    (4, "applications", ("texsense.apps",)),
    (5, "live", ("texsense.monitor", "texsense.station")),
    (6, "command line", ("texsense.commands", "texsense.cli", "texsense.__main__")),
]  # fmt: skip


def layer_of(module: str) -> tuple[int, str]:
    """(rank, group) of a texsense module: its longest matching prefix in LAYERS."""
    best: tuple[int, int, str] | None = None
    for rank, group, prefixes in LAYERS:
        for p in prefixes:
            exact_root = p == "texsense" and module == "texsense"
            inside = p != "texsense" and (module == p or module.startswith(p + "."))
            if (exact_root or inside) and (best is None or len(p) > best[0]):
                best = (len(p), rank, group)
    assert best is not None, f"{module} is in no layer of LAYERS"
    return best[1], best[2]


def upward_imports() -> list[str]:
    """The imports (module level or inside functions) that point up or sideways."""
    bad = []
    for name, targets in graph().items():
        rank, group = layer_of(name)
        for t in sorted(targets):
            t_rank, t_group = layer_of(t)
            if t_group != group and t_rank >= rank:
                bad.append(f"{name} ({group}) imports {t} ({t_group})")
    return bad


def test_every_module_belongs_to_a_layer():
    for name in modules():
        layer_of(name)


def test_the_layers_point_one_way():
    assert upward_imports() == []


def test_the_layer_check_sees_an_upward_import():
    assert layer_of("texsense.apps.bed") == (4, "applications")
    assert layer_of("texsense.data.layout") == (1, "data")
    assert layer_of("texsense") == (0, "base")
    assert layer_of("texsense.sim.spacer") == (2, "physics")
    assert layer_of("texsense.compensation.drift")[1] == "compensation"


def test_the_old_import_paths_warn_and_give_the_same_module():
    code = (
        "import warnings, json\n"
        "with warnings.catch_warnings(record=True) as w:\n"
        "    warnings.simplefilter('always')\n"
        "    from texsense.stages import StageChain\n"
        "    import texsense.posture.features as old_features\n"
        "    from texsense import bed\n"
        "    from texsense.calibration import fit_conversion\n"
        "import texsense.apps.bed, texsense.apps.posture.features\n"
        "from texsense.compensation.stages import StageChain as New\n"
        "from texsense.compensation.conversion import fit_conversion as new_fit\n"
        "same = [StageChain is New, bed is texsense.apps.bed,\n"
        "        old_features is texsense.apps.posture.features, fit_conversion is new_fit,\n"
        "        old_features.__spec__.name == 'texsense.apps.posture.features']\n"
        "print('RESULT', json.dumps([same, sorted({str(x.category.__name__) for x in w}),\n"
        "      [str(x.message) for x in w]]))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120
    ).stdout
    line = next(x for x in out.splitlines() if x.startswith("RESULT"))
    same, categories, messages = json.loads(line[len("RESULT ") :])
    assert all(same), same
    assert categories == ["DeprecationWarning"]
    assert "texsense.stages moved to texsense.compensation.stages" in messages[0]
    assert any("texsense.bed moved to texsense.apps.bed" in m for m in messages)
    assert any("fit_conversion moved to texsense.compensation.conversion" in m for m in messages)
