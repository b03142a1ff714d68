"""
The README is a short front door, and every link in it and in docs/ resolves.

Relative links must name an existing file, and an anchor (``page.md#heading``) an
existing heading of that page (GitHub's anchor rule: lower case, punctuation dropped,
spaces to hyphens).
"""

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
