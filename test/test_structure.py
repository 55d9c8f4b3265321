"""The package's shape: no import cycles, no private names across modules, core/ free of
ROS and of the evaluation, modules and functions of a readable size.

Imports are read with `ast` (nothing is imported), function-level imports included.
"""
from __future__ import annotations

import ast
from functools import lru_cache
from pathlib import Path

PACKAGE = 'asmonc_vision'
ROOT = Path(__file__).resolve().parent.parent / PACKAGE
MAX_MODULE_LINES = 1000
MAX_FUNCTION_LINES = 100

#: functions over MAX_FUNCTION_LINES, to be split; only shrinks
LONG_FUNCTIONS_PENDING: set[tuple[str, str]] = set()
#: private names that modules of their own subpackage import, to be made public (or kept
#: in one module); module (without the package) -> names. Only shrinks.
PRIVATE_IMPORTS_PENDING: dict[str, tuple[str, ...]] = {
    'core.gait.kernels': ('_NO_ACCEL_VAR', '_NO_TABLE'),
    'core.gait.state': ('_D2R',),
    'core.gpod.coarse': ('_coarse_consistent', '_disparity_image'),
    'core.gpod.faces': ('_ground_points',),
    'core.gpod.footing': ('_FrameContext', '_LONE_STEP_M'),
    'core.gpod.grouping': ('_brink_bearings', '_fit_line', '_group_quantile', '_normal_cdf',
                           '_same_object'),
    'core.gpod.kernels_geometry': ('_ARC_LIN', '_BODY_GAP_BAND_M', '_BODY_GAP_END_M',
                                   '_BODY_GAP_SPAN_M', '_CORNER_SIGMAS', '_FACE_BEHIND_MIN',
                                   '_FACE_HIDDEN_MIN', '_FREE_SPACE_MARGIN_M',
                                   '_WEAK_HEIGHT_RATIO', '_face_hides_kernel'),
    'core.gpod.nearest': ('_body_gap', '_ground_inside'),
    'core.gpod.runs': ('_TRUE', '_robust_row_slope'),
    'core.gpod.support': ('_Pass', '_below_view', '_features',
                          '_mad_sigma', '_moved_roi', '_noise_key', '_planes_agree',
                          '_state_metric', '_still_motion'),
}
#: what core/ must not import: ROS, messages, bags, and the layers above it
CORE_FORBIDDEN = ('rclpy', 'rosbags', 'asmonc_vision_msgs', 'sensor_msgs', 'geometry_msgs',
                  'std_msgs', 'nav_msgs', 'visualization_msgs', 'diagnostic_msgs',
                  f'{PACKAGE}.eval', f'{PACKAGE}.cli', f'{PACKAGE}.nodes', f'{PACKAGE}.io',
                  f'{PACKAGE}.sim', f'{PACKAGE}.faults', f'{PACKAGE}.graph')


def _private_pending(name: str, base: str, item: str) -> bool:
    """Whether module ``name``'s import of ``base.item`` is listed in
    PRIVATE_IMPORTS_PENDING (and ``name`` is of ``base``'s subpackage)."""
    return (item in PRIVATE_IMPORTS_PENDING.get(base.removeprefix(f'{PACKAGE}.'), ())
            and name.rpartition('.')[0] == base.rpartition('.')[0])


@lru_cache(maxsize=1)
def modules() -> dict[str, tuple[Path, ast.Module]]:
    """Dotted module name -> (path, parsed tree) for every module of the package."""
    out = {}
    for path in sorted(ROOT.rglob('*.py')):
        parts = path.relative_to(ROOT.parent).with_suffix('').parts
        if parts[-1] == '__init__':
            parts = parts[:-1]
        out['.'.join(parts)] = (path, ast.parse(path.read_text(), str(path)))
    return out


def _base(name: str, path: Path, node: ast.ImportFrom) -> str:
    """The absolute module an ``ImportFrom`` names (relative imports resolved)."""
    if not node.level:
        return node.module or ''
    parts = name.split('.')
    if path.name != '__init__.py':
        parts = parts[:-1]
    parts = parts[:len(parts) - (node.level - 1)]
    return '.'.join(parts + ([node.module] if node.module else []))


def _type_only(tree: ast.Module) -> set[int]:
    """ids of the import nodes under ``if TYPE_CHECKING:`` (for the type checker only: they
    never run, so they make no cycle)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and 'TYPE_CHECKING' in ast.unparse(node.test):
            out |= {id(n) for b in node.body for n in ast.walk(b)}
    return out


def imports(name: str) -> list[tuple[str, str | None]]:
    """(imported module, imported name or None) of every import in a module that runs
    (at module level or in a function; not the type checker's own)."""
    path, tree = modules()[name]
    out: list[tuple[str, str | None]] = []
    skip = _type_only(tree)
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out += [(a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = _base(name, path, node)
            out += [(base, a.name) for a in node.names]
    return out


def dependencies(name: str) -> set[str]:
    """The package's modules a module imports (``from pkg import mod`` counts as mod)."""
    mods = modules()
    out = set()
    for base, item in imports(name):
        if item is not None and f'{base}.{item}' in mods:
            out.add(f'{base}.{item}')
        elif base in mods:
            out.add(base)
    return out - {name}


def cycles() -> list[list[str]]:
    """Strongly connected groups of more than one module (Tarjan)."""
    graph = {m: dependencies(m) for m in modules()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                found.append(sorted(group))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def _rel(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


def test_the_import_graph_is_read():
    deps = dependencies(f'{PACKAGE}.cli.main')
    assert f'{PACKAGE}.cli.run' in deps        # a function-level import counts
    assert len(modules()) > 50


def test_no_import_cycles():
    assert cycles() == []


def test_a_cycle_would_be_found(monkeypatch):
    import test_structure as me
    real = me.dependencies
    a, b = f'{PACKAGE}.io.bagio', f'{PACKAGE}.io.frames'
    monkeypatch.setattr(me, 'dependencies',
                        lambda m: real(m) | ({b} if m == a else set()))
    assert [a, b] in me.cycles()


def private_imports() -> list[tuple[str, str, str]]:
    """(importing module, imported module, private name) of every import of a private
    name of the package from another of its modules."""
    out = []
    for name in modules():
        for base, item in imports(name):
            if (item and item.startswith('_') and not item.startswith('__')
                    and base.startswith(PACKAGE) and base != name):
                out.append((name, base, item))
    return out


def test_no_private_names_across_modules():
    found = [f'{name} imports {base}.{item}' for name, base, item in private_imports()
             if not _private_pending(name, base, item)]
    assert found == []


def test_the_pending_private_names_are_imported_across_modules():
    """A private name no longer imported from another module leaves
    PRIVATE_IMPORTS_PENDING (the list only shrinks)."""
    used = {(base.removeprefix(f'{PACKAGE}.'), item) for _, base, item in private_imports()}
    listed = {(mod, item) for mod, names in PRIVATE_IMPORTS_PENDING.items() for item in names}
    assert listed - used == set()


def test_core_imports_no_ros_messages_or_evaluation():
    found = []
    for name in modules():
        if not name.startswith(f'{PACKAGE}.core'):
            continue
        for base, _ in imports(name):
            if base.startswith(CORE_FORBIDDEN):
                found.append(f'{name} imports {base}')
    assert found == []


def test_modules_are_at_most_1000_lines():
    long = {_rel(p): n for p, _ in modules().values()
            if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES}
    assert long == {}


def long_functions() -> set[tuple[str, str]]:
    out = set()
    for path, tree in modules().values():
        for node in ast.walk(tree):
            if (isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
                    and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES):
                out.add((_rel(path), node.name))
    return out


def test_functions_are_at_most_100_lines():
    assert long_functions() - LONG_FUNCTIONS_PENDING == set()


def test_the_pending_list_only_names_long_functions():
    """A function split since must leave LONG_FUNCTIONS_PENDING (the list only shrinks)."""
    assert LONG_FUNCTIONS_PENDING - long_functions() == set()
