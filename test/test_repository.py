"""The repository as a product: a short README, reference docs whose tables and figures
come from commands, no notebook left behind."""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from mbtrack_ros.commands.benchmarks import BENCHMARKS

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / 'README.md', *sorted((REPO / 'docs').rglob('*.md'))]


def test_readme_is_short_and_starts_with_the_two_commands_and_your_own_room():
    lines = (REPO / 'README.md').read_text(encoding='utf-8').splitlines()
    assert len(lines) <= 250
    first_screen = '\n'.join(lines[:60])
    assert 'python3 -m mbtrack_ros.bootstrap demo' in first_screen
    assert 'python3 -m mbtrack_ros.bootstrap test' in first_screen
    assert '## Your own room' in '\n'.join(lines[:70])


def test_docs_are_reference_not_a_notebook():
    docs = REPO / 'docs'
    assert sum(len(p.read_text(encoding='utf-8').splitlines())
               for p in docs.rglob('*.md')) <= 3000
    assert not (docs / 'diag').exists()
    assert not list(REPO.rglob('*.patch'))
    assert not list(docs.glob('*.py'))


def test_no_history_words():
    word = 'sess' + 'ion'   # not spelled out here, so that this file passes its own check
    pattern = re.compile(rf'\b{word}s?\b', re.I)
    found = subprocess.run(['git', 'ls-files'], cwd=REPO, capture_output=True, text=True)
    if found.returncode == 0:
        names = found.stdout.splitlines()
    else:  # not a git checkout (an unpacked source tree): the project's own folders
        names = [str(p.relative_to(REPO)) for top in ('mbtrack_ros', 'docs', 'test', 'config',
                                                      'launch', 'interfaces')
                 for p in (REPO / top).rglob('*') if p.is_file()]
        names += [p.name for p in REPO.glob('*.md')]
    assert names
    offenders = []
    for name in names:
        path = REPO / name
        if path.suffix in {'.py', '.md', '.yaml', '.cfg', '.xml', '.txt'} and path.exists():
            if pattern.search(path.read_text(encoding='utf-8', errors='replace')):
                offenders.append(name)
    assert offenders == []


@pytest.mark.parametrize('page', PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_results_blocks_name_benchmarks_and_images_exist(page):
    text = page.read_text(encoding='utf-8')
    names = {b.name for b in BENCHMARKS}
    for name, body in re.findall(r'<!-- results: (\w+) -->\n(.*?)<!-- /results -->', text,
                                 re.S):
        assert name in names, name
        assert '`mbtrack evaluate' in body, f'{page.name}: block {name} is not filled'
    for target in re.findall(r'!\[[^\]]*\]\(([^)]+)\)', text):
        assert (page.parent / target).exists(), f'{page.name}: {target} missing'
