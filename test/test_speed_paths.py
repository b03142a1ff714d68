"""
The speed rules (docs/benchmarks.md): pure Python, one BLAS thread, no timings in code.

A compiled or threaded path stays only where it pays 1.5x end to end on its command;
none did, so the package builds without a C compiler.  Thread control is the
environment (OPENBLAS_NUM_THREADS, set by the entry points before numpy loads), and
timings live in docs/benchmarks.md only, never in comments or docstrings.
"""

import ast
import io
import os
from pathlib import Path
import re
import subprocess
import sys
import tokenize

import numpy as np

from conftest import REPO

PACKAGE = REPO / 'imu_allan'

#: A figure of time or speed: "5 us", "0.6 s of", "1.5x slower", "M msg/s", "rows/s".
TIMING = re.compile(r'\b\d[\d.,]*\s?(ms|us|µs)\b'
                    r'|\b\d[\d.,]*\s?s (of|per|for|instead|against|wall|CPU)\b'
                    r'|\b\d[\d.,]*\s?x (faster|slower|cheaper|quicker|the)\b'
                    r'|\b(twice|three times|four times|\d+ times) (as fast|faster|slower)\b'
                    r'|msg/s|rows/s|samples/s|GB/s|MB/s')


def _comment_text(path: Path) -> list:
    """Return (line, text) of every comment and docstring of a module."""
    source = path.read_text()
    out = [(tok.start[0], tok.string) for tok in
           tokenize.generate_tokens(io.StringIO(source).readline)
           if tok.type == tokenize.COMMENT]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                             ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc:
                out.append((getattr(node, 'lineno', 1), doc))
    return out


def test_no_timing_claims_in_comments_or_docstrings():
    found = [f'{path.relative_to(REPO)}:{line}: {m.group(0)!r}'
             for path in sorted(PACKAGE.rglob('*.py'))
             for line, text in _comment_text(path)
             for m in TIMING.finditer(text)]
    assert not found, 'timings belong in docs/benchmarks.md:\n' + '\n'.join(found)


def test_the_package_is_pure_python():
    # No C source, no extension module, no build dependency on a compiler or headers.
    assert not [p for p in PACKAGE.rglob('*') if p.suffix in ('.c', '.h', '.pyx')]
    setup = ast.parse((REPO / 'setup.py').read_text())
    keywords = {kw.arg for node in ast.walk(setup) if isinstance(node, ast.Call)
                for kw in node.keywords}
    assert 'packages' in keywords and 'ext_modules' not in keywords
    package_xml = (REPO / 'package.xml').read_text()
    assert 'python3-dev' not in package_xml and '<build_depend>' not in package_xml


_ONE_THREAD = """
import contextlib, ctypes, io, os, sys
from pathlib import Path
from imu_allan.cli import main
assert 'numpy' not in sys.modules
with contextlib.redirect_stdout(io.StringIO()):
    assert main(['adev', sys.argv[1], '--rate', '100', '--format', 'json']) == 0
print('env', os.environ.get('OPENBLAS_NUM_THREADS'))
# The OpenBLAS numpy loaded, asked directly (the test may look where the package does not).
paths = {ln.split()[-1] for ln in Path('/proc/self/maps').read_text().splitlines()
         if 'openblas' in ln.lower()}
for path in sorted(paths):
    lib = ctypes.CDLL(path)
    for name in ('scipy_openblas_get_num_threads64_', 'openblas_get_num_threads64_',
                 'openblas_get_num_threads'):
        if hasattr(lib, name):
            print('threads', getattr(lib, name)())
            break
"""


def test_the_cli_holds_openblas_to_one_thread(tmp_path):
    # Set before the command's module loads numpy, so OpenBLAS starts with one thread.
    column = tmp_path / 'column.csv'
    rng = np.random.default_rng(3)
    np.savetxt(column, rng.normal(size=2000), fmt='%.9e')
    env = {k: v for k, v in os.environ.items()
           if k not in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS')}
    run = subprocess.run([sys.executable, '-c', _ONE_THREAD, str(column)], cwd=REPO, env=env,
                         capture_output=True, text=True, check=True)
    lines = run.stdout.split()
    assert lines[:2] == ['env', '1'], run.stdout
    assert lines[2::2] == ['threads'] * (len(lines) // 2 - 1) and set(lines[3::2]) <= {'1'}
