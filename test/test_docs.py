"""The docs agree with the code: the generated parameter doc is current, the QoS table
matches the publishers, the README has its results markers and stays short, every repo
path the docs name exists, and no work-log references sit in the project's files."""
from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

from asmonc_vision import paramdoc
from asmonc_vision.cli.main import main as asmonc_main

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / 'docs'
README = ROOT / 'README.md'


#: a dated note, a numbered work period or issue, an experiment log entry
WORK_LOG = re.compile(r'\b[Ss]ession[ -]\d+|\b[Ii]ssue #?\d+|[Tt]ried, not kept'
                      r'|\b20[2-9]\d-[01]\d-[0-3]\d\b(?!T)')


def _doc_files() -> list[Path]:
    return [README, *sorted(DOCS.glob('*.md'))]


def test_parameters_md_is_the_output_of_asmonc_params(capsys):
    assert asmonc_main(['params', '--markdown']) == 0
    out = capsys.readouterr().out
    assert out == paramdoc.render_markdown()
    assert (DOCS / 'parameters.md').read_text() == out, (
        'docs/parameters.md is stale: run `asmonc params --markdown > docs/parameters.md`')


def test_params_cover_every_node_config_file():
    named = {Path(yaml).name for _node, yaml, _specs in paramdoc.NODES}
    assert named == {p.name for p in (ROOT / 'config').glob('*.yaml')}
    for node, _yaml, _specs in paramdoc.NODES:
        rows = paramdoc.rows(node)
        assert rows, node
        assert all(desc for _n, _d, _r, desc, _c in rows), node


def _qos_table() -> list[list[str]]:
    text = (DOCS / 'CONVENTIONS.md').read_text()
    section = text.split('## QoS', 1)[1].split('\n## ', 1)[0]
    rows = []
    for line in section.splitlines():
        cells = [c.strip().strip('`') for c in line.strip().strip('|').split('|')]
        if len(cells) == 6 and cells[0].startswith('/'):
            rows.append(cells)
    return rows


_PUBLISHER = re.compile(r'create_publisher\(\s*\w+,\s*([^,()]+?),\s*(\w+)\s*\)', re.S)


def _publishers(module_name: str) -> dict[str, tuple[str, object]]:
    """topic -> (profile name, profile) for every create_publisher in a node module."""
    module = importlib.import_module(f'asmonc_vision.nodes.{module_name}')
    source = Path(module.__file__).read_text()
    out = {}
    for topic_expr, profile_name in _PUBLISHER.findall(source):
        topic_expr = topic_expr.strip()
        if topic_expr[0] in '\'"':
            topic = topic_expr[1:-1]
        elif hasattr(module, topic_expr):
            topic = getattr(module, topic_expr)
        else:
            continue            # a topic chosen at run time (player, recorder)
        if profile_name.isdigit():
            continue            # /diagnostics with the default profile
        out[topic] = (profile_name, getattr(module, profile_name))
    return out


def test_conventions_qos_table_matches_the_publishers():
    rows = _qos_table()
    assert len(rows) >= 10
    tabled = set()
    for topic, module_name, profile_name, reliability, durability, depth in rows:
        pubs = _publishers(module_name)
        assert topic in pubs, f'{module_name} does not publish {topic}'
        name, profile = pubs[topic]
        assert name == profile_name, (topic, name, profile_name)
        assert profile.reliability.name == reliability, (topic, profile.reliability)
        assert profile.durability.name == durability, (topic, profile.durability)
        assert profile.depth == int(depth), (topic, profile.depth)
        tabled.add(topic)
    # every fixed-QoS publisher of the nodes is in the table
    for path in sorted((ROOT / 'asmonc_vision' / 'nodes').glob('*_node.py')):
        for topic in _publishers(path.stem):
            assert topic in tabled, f'{topic} ({path.name}) is missing from the QoS table'


def test_alarm_qos_is_latched_depth_one():
    row = next(r for r in _qos_table() if r[0] == '/alarms')
    assert row[3:] == ['RELIABLE', 'TRANSIENT_LOCAL', '1']


def test_readme_is_short_and_has_the_results_markers():
    text = README.read_text()
    assert len(text.splitlines()) <= 220
    begin, end = '<!-- results:begin -->', '<!-- results:end -->'
    assert text.count(begin) == 1 and text.count(end) == 1
    assert text.index(begin) < text.index(end)
    assert 'asmonc campaign' in text[:text.index(begin)].rsplit('##', 1)[1]
    assert max(len(line) for line in text.splitlines()) < 400


_PATH = re.compile(r'`([A-Za-z_][\w.\-/]*/[\w.\-/]*)`')
_BASES = ('', 'asmonc_vision/', 'asmonc_vision/core/', 'docs/')
#: first parts of a path inside this repository (top-level folders, asmonc_vision's packages)
_REPO_DIRS = {'asmonc_vision', 'docs', 'config', 'test', 'launch', 'msg', 'bags', 'core',
              'nodes', 'cli', 'sim', 'eval', 'motion', 'gait', 'audio', '.ci'}


def _named_paths(text: str) -> set[str]:
    """Backquoted paths that start in a folder of this repository."""
    return {token for token in _PATH.findall(text)
            if token.split('/', 1)[0] in _REPO_DIRS and '*' not in token}


@pytest.mark.parametrize('doc', _doc_files(), ids=lambda p: p.name)
def test_every_repo_path_named_in_the_docs_exists(doc):
    def exists(p: str) -> bool:
        head, _, name = p.rpartition('/')
        module = f'{head}/{name.split(".", 1)[0]}.py'      # core/camera.ground_range_bearing
        return any((ROOT / base / q).exists() for base in _BASES for q in (p, module))

    missing = [p for p in sorted(_named_paths(doc.read_text())) if not exists(p)]
    assert not missing, f'{doc.name} names paths that do not exist: {missing}'


def _project_files() -> list[Path]:
    files = [README, *DOCS.glob('*.md')]
    for top in ('asmonc_vision', 'test', 'config', 'launch'):
        files += [p for p in (ROOT / top).rglob('*')
                  if p.is_file() and p.suffix in ('.py', '.md', '.yaml', '.txt')
                  and '__pycache__' not in p.parts]
    return sorted(files)


def test_no_work_log_references():
    found = []
    for path in _project_files():
        rel = path.relative_to(ROOT).as_posix()
        if rel == 'test/test_docs.py':
            continue
        for i, line in enumerate(path.read_text(errors='replace').splitlines(), 1):
            if WORK_LOG.search(line):
                found.append(f'{rel}:{i}: {line.strip()[:100]}')
    assert not found, 'work-log references:\n' + '\n'.join(found)


def test_work_log_pattern_catches_what_it_names():
    period = 'Session'            # the word the pattern looks for, in both spellings
    for bad in (f'as in {period.lower()} 37', f'the {period.lower()}-12 kernels',
                f'{period} 4', 'Issue 48 asks', 'Tried, not kept: x', 'on 2026-01-05'):
        assert WORK_LOG.search(bad), bad
    for fine in (f'{period.lower()}s of walking', 'a stamp of 2023-11-14T22:13:20Z',
                 'no issue here'):
        assert not WORK_LOG.search(fine), fine
