"""
The README is a short front door, and every link, path and name in it and in docs/ resolves.

Relative links must name an existing file, and an anchor (``page.md#heading``) an
existing heading of that page (GitHub's anchor rule: lower case, punctuation dropped,
spaces to hyphens).  The map of docs/architecture.md is true: every path of its tree
exists and every module of the package is on it; every dotted name ``imu_allan.x.y``
the docs cite imports.
"""

import importlib
import re

import pytest

from conftest import REPO

PAGES = [REPO / 'README.md'] + sorted((REPO / 'docs').glob('*.md'))
LINK = re.compile(r'\[[^\]]*\]\(([^)\s]+)\)')


def _anchors(path) -> set:
    text, fence, out = path.read_text(), False, set()
    for line in text.split('\n'):
        if line.startswith('```'):
            fence = not fence
        if not fence and line.startswith('#'):
            title = line.lstrip('#').strip().lower()
            out.add(re.sub(r'\s', '-', re.sub(r'[^\w\s-]', '', title)))
    return out


def test_readme_is_a_short_front_door():
    text = (REPO / 'README.md').read_text()
    assert len(text.encode()) < 10_000
    assert 'make demo' in text and 'make test' in text


@pytest.mark.parametrize('page', PAGES, ids=lambda p: p.name)
def test_every_relative_link_resolves(page):
    bad = []
    for target in LINK.findall(page.read_text()):
        if re.match(r'^[a-z]+://', target) or target.startswith('mailto:'):
            continue
        path, _, anchor = target.partition('#')
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            bad.append(target)
        elif anchor and dest.suffix == '.md' and anchor not in _anchors(dest):
            bad.append(target)
    assert not bad, bad


def test_link_check_can_fail(tmp_path):
    page = tmp_path / 'p.md'
    page.write_text('# Title\n\n[x](missing.md) [y](#title) [z](#nope)\n')
    found = LINK.findall(page.read_text())
    assert found == ['missing.md', '#title', '#nope']
    assert 'title' in _anchors(page) and 'nope' not in _anchors(page)


#: A path of the repository named in a doc: `imu_allan/...`, `bench/...` and the like.
CODE_PATH = re.compile(r'(?<![\w./-])((?:imu_allan|bench|test|docs|config|launch|tools)'
                       r'/[\w./-]*\w)')


def _named_paths(text: str) -> set:
    return {m.rstrip('.') for m in CODE_PATH.findall(text)}


@pytest.mark.parametrize('page', PAGES, ids=lambda p: p.name)
def test_every_code_path_a_doc_names_exists(page):
    missing = sorted(p for p in _named_paths(page.read_text())
                     if '*' not in p and not (REPO / p).exists())
    assert not missing, missing


def test_code_path_check_can_fail():
    found = _named_paths('see `imu_allan/core/fit.py` and imu_allan/core/allan/, not '
                         'x/imu_allan/y or ../shared/DESIGN.md.')
    assert found == {'imu_allan/core/fit.py', 'imu_allan/core/allan/'} or \
        found == {'imu_allan/core/fit.py', 'imu_allan/core/allan'}
    assert not (REPO / 'imu_allan/core/fit.py').exists()


def test_no_reference_outside_the_repository():
    # A user's clone has no ../shared: neither docs nor code may send them there.
    files = PAGES + sorted((REPO / 'imu_allan').rglob('*.py'))
    bad = [str(f.relative_to(REPO)) for f in files
           if 'DESIGN.md' in f.read_text()]
    assert not bad, bad


#: A line of the tree in docs/architecture.md that names an entry: its indentation (two
#: spaces per level) and a directory (``name/``) or a file (``name.ext``).
TREE_ENTRY = re.compile(r'^( *)([\w.]+/|\w+\.\w+)(?:\s|$)')


def _tree(text: str) -> dict:
    """
    Return {path: description} of the tree block, paths built from the indentation.

    A line indented deeper than one level below the previous entry continues its
    description.
    """
    block = text.split('```')[1]
    out: dict = {}
    stack: list = []
    last, path = -2, ''
    for line in block.split('\n'):
        m = TREE_ENTRY.match(line)
        if m and len(m.group(1)) <= last + 2 and len(m.group(1)) % 2 == 0:
            stack = stack[:len(m.group(1)) // 2] + [m.group(2)]
            last, path = len(m.group(1)), ''.join(stack)
            out[path] = line[m.end():]
        elif path:
            out[path] += ' ' + line.strip()
    return out


def test_every_path_of_the_map_exists():
    tree = _tree((REPO / 'docs' / 'architecture.md').read_text())
    assert len(tree) > 50
    missing = sorted(p for p in tree if not (REPO / p.rstrip('/')).exists())
    assert not missing, missing


def test_every_module_is_on_the_map():
    # A module is an entry of the tree, or named in its directory's description.
    tree = _tree((REPO / 'docs' / 'architecture.md').read_text())
    absent = []
    for path in sorted((REPO / 'imu_allan').rglob('*')):
        if path.suffix not in ('.py', '.c') or path.name == '__init__.py':
            continue
        rel = str(path.relative_to(REPO))
        folder = str(path.parent.relative_to(REPO)) + '/'
        if rel not in tree and not re.search(rf'\b{path.stem}\b', tree.get(folder, '')):
            absent.append(rel)
    assert not absent, absent


def test_tree_check_can_fail():
    text = ('```\nimu_allan/\n  core/            numpy, see kernels\n'
            '    fit.py           a file that is not there,\n'
            '                     described on two lines\n  io/\n```\n')
    tree = _tree(text)
    assert list(tree) == ['imu_allan/', 'imu_allan/core/', 'imu_allan/core/fit.py',
                          'imu_allan/io/']
    assert 'two lines' in tree['imu_allan/core/fit.py']
    assert 'kernels' in tree['imu_allan/core/']
    assert not (REPO / 'imu_allan/core/fit.py').exists()


#: A dotted name of the package cited in a doc: ``imu_allan.core.fit.fit_axis``.
DOTTED = re.compile(r'\bimu_allan(?:\.[A-Za-z_]\w*)+')
#: Endings that make a dotted name a file (``imu_allan.launch.py``), not a Python name.
FILE_SUFFIXES = ('py', 'yaml', 'md', 'json')


def _resolves(dotted: str) -> bool:
    """Whether a dotted name imports: the longest module prefix, then attributes."""
    parts = dotted.split('.')
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module('.'.join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def _cited(text: str) -> set:
    return {m for m in DOTTED.findall(text) if m.rpartition('.')[2] not in FILE_SUFFIXES}


@pytest.mark.parametrize('page', PAGES, ids=lambda p: p.name)
def test_every_dotted_name_a_doc_cites_imports(page):
    bad = sorted(name for name in _cited(page.read_text()) if not _resolves(name))
    assert not bad, bad


def test_dotted_name_check_can_fail():
    found = _cited('`imu_allan.pipeline.Session`, imu_allan.core.fit.fit_axis, '
                   'imu_allan.launch.py and imu_allan.AXES.')
    assert found == {'imu_allan.pipeline.Session', 'imu_allan.core.fit.fit_axis',
                     'imu_allan.AXES'}
    assert not _resolves('imu_allan.pipeline.Session')
    assert _resolves('imu_allan.core.fit.fit_axis') and _resolves('imu_allan.AXES')


# ------------------------------------------------- figures the docs quote, re-run
def _doc(name: str) -> str:
    return (REPO / 'docs' / name).read_text()


def test_the_six_run_table_of_offline_md_holds_todays_run_1(adis_run1):
    # docs/offline.md quotes comparison.md of `imu-allan analyze run1.csv.gz ... run6`:
    # its run1 column is re-run here (the other runs are the same code on other data).
    rows = [[c.strip() for c in line.strip().strip('|').split('|')]
            for line in _doc('offline.md').splitlines()
            if re.match(r'\s*\| (gyro|accel)_[xyz] \| ', line)]
    table = [r for r in rows if len(r) == 12]
    assert len(table) >= 5
    for axis, sym, unit, run1, *_ in table:
        p = adis_run1.fits[axis].optimised[sym]
        assert p.kind == 'estimate' and p.unit == unit, (axis, sym, p)
        assert float(run1) == pytest.approx(p.value, rel=1e-3), (axis, sym, run1, p.value)


def test_the_vins_values_of_outputs_md_are_todays_run_1(adis_run1):
    text = ' '.join(_doc('outputs.md').split())
    written = dict(re.findall(r'^(\w+): ([-+.\de]+)', adis_run1.vins_yaml(), re.M))
    number = r'(\d[\d.e+-]*\d)'         # a figure, not the full stop after it
    quoted = dict(re.findall(r'`(\w+)`(?: went)? (?:was|from) \d[\d.e+-]*\d(?: \(the '
                             r'density\))? (?:and is now|to) ' + number, text))
    assert set(quoted) == {'gyr_n', 'gyr_w', 'acc_n', 'acc_w'}, quoted
    for key, value in quoted.items():
        assert float(value) == pytest.approx(float(written[key]), rel=1e-3), key
    factors = re.search(r'covering factors ([\d.]+) \(gyro N\), ([\d.]+) \(gyro K\), '
                        r'([\d.]+) \(accel N\), ([\d.]+) \(accel K\)', text)
    got = re.findall(r'factor N ([\d.]+), K ([\d.]+)', adis_run1.vins_yaml())
    (acc_n, acc_k), (gyr_n, gyr_k) = got
    assert [float(f) for f in factors.groups()] == pytest.approx(
        [float(gyr_n), float(gyr_k), float(acc_n), float(acc_k)], rel=0.01)
