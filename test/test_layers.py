"""
Layers by package: adapters (io, ros, cli) -> pipeline -> core, never the other way.

Two checks:
- every module of ``imu_allan.core`` and ``imu_allan.pipeline`` (and the node's ROS-free
  parameter table) imports in a subprocess whose import machinery refuses every ROS, bag
  and plotting module, so a stray import anywhere in them fails here;
- every ``import`` statement in the package, lazy ones inside functions included, points
  only at layers its own layer may use.
"""

import ast
from pathlib import Path
import subprocess
import sys

from conftest import REPO

PKG = Path(REPO) / 'imu_allan'
#: Which of the package's layers each layer may import (the package root and errors are
#: shared by all).
ALLOWED = {
    'core': {'core'},
    'pipeline': {'core', 'pipeline'},
    'io': {'core', 'pipeline', 'io'},
    'ros': {'core', 'pipeline', 'io', 'ros'},
    'fleet': {'core', 'pipeline', 'io', 'fleet'},
    'cli': {'core', 'pipeline', 'io', 'ros', 'fleet', 'cli'},
}
ROS_FREE = ('imu_allan.ros.params',)
#: The node's input side imports no rclpy (it is driven by plain bytes in tests).
NO_RCLPY = ('imu_allan.ros.live',)
FORBIDDEN = ('rclpy', 'rosbags', 'mcap', 'sensor_msgs', 'std_msgs', 'std_srvs',
             'diagnostic_msgs', 'builtin_interfaces', 'matplotlib', 'launch', 'lz4',
             'zstandard', 'dask', 'distributed')

SCRIPT = f"""
import importlib, pkgutil, sys
FORBIDDEN = {FORBIDDEN!r}

class Refuse:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in FORBIDDEN:
            raise ImportError('core imported ' + name)
        return None

sys.meta_path.insert(0, Refuse())
import imu_allan.core, imu_allan.pipeline
names = list({ROS_FREE!r})
for pkg in (imu_allan.core, imu_allan.pipeline):
    names += [m.name for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + '.')]
for name in names:
    importlib.import_module(name)
print('ok', len(names))
"""


def _layer(module: str) -> str | None:
    parts = module.split('.')
    return parts[1] if len(parts) > 1 and parts[0] == 'imu_allan' and parts[1] in ALLOWED \
        else None


def _module(path: Path) -> str:
    return '.'.join(path.relative_to(PKG.parent).with_suffix('').parts)


def _imports(path: Path, module: str):
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split('.')[:-node.level]
                yield '.'.join(base + ([node.module] if node.module else []))
            else:
                yield node.module


def test_core_and_pipeline_import_without_ros():
    out = subprocess.run([sys.executable, '-c', SCRIPT], cwd=REPO, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith('ok'), out.stdout
    assert int(out.stdout.split()[1]) >= 12


def test_refusal_really_works():
    # The guard itself must be able to fail: importing rclpy under it is refused.
    script = SCRIPT.replace("print('ok', len(names))", 'import rclpy')
    out = subprocess.run([sys.executable, '-c', script], cwd=REPO, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode != 0 and 'core imported rclpy' in out.stderr


def test_imports_point_down_the_layers():
    bad = []
    for path in sorted(PKG.rglob('*.py')):
        own = _layer(_module(path))
        if own is None:
            continue
        for target in _imports(path, _module(path)):
            layer = _layer(target or '')
            if layer is not None and layer not in ALLOWED[own]:
                bad.append(f'{path.relative_to(PKG.parent)} imports {target}')
    assert not bad, '\n'.join(bad)


def test_layer_check_can_fail(tmp_path):
    # The scan sees lazy imports inside functions, relative ones included.
    src = tmp_path / 'x.py'
    src.write_text('def f():\n    from imu_allan.ros.node import main\n'
                   '    from ..io import plot\n')
    targets = list(_imports(src, 'imu_allan.core.x'))
    assert targets == ['imu_allan.ros.node', 'imu_allan.io']
    assert all(_layer(t) not in ALLOWED['core'] for t in targets)


def test_live_input_and_fleet_free_of_what_they_must_not_need():
    # The node's input side runs without rclpy; the node and the core never import Dask.
    script = SCRIPT.replace(
        f'FORBIDDEN = {FORBIDDEN!r}',
        "FORBIDDEN = ('rclpy', 'sensor_msgs', 'std_msgs', 'dask', 'distributed', 'pyarrow')"
    ).replace(f'names = list({ROS_FREE!r})', f'names = list({NO_RCLPY!r})').replace(
        'for pkg in (imu_allan.core, imu_allan.pipeline):', 'for pkg in ():')
    out = subprocess.run([sys.executable, '-c', script], cwd=REPO, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    node = (PKG / 'ros' / 'node.py').read_text()
    assert 'fleet' not in node and 'dask' not in node


def _modules() -> dict:
    """Return {dotted module name: path} of every module of the package."""
    out = {}
    for path in PKG.rglob('*.py'):
        name = _module(path)
        out[name[:-len('.__init__')] if name.endswith('.__init__') else name] = path
    return out


def _import_graph(modules: dict) -> dict:
    """Return {module: modules it imports}, lazy imports included, at module granularity."""
    graph = {}
    for name, path in modules.items():
        own = name if path.name == '__init__.py' else name.rpartition('.')[0]
        edges = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                edges.update(a.name for a in node.names if a.name in modules)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ''
                if node.level:
                    parts = own.split('.')[:len(own.split('.')) - node.level + 1]
                    base = '.'.join(parts + ([node.module] if node.module else []))
                for alias in node.names:
                    target = f'{base}.{alias.name}'
                    edges.add(target if target in modules else base)
        graph[name] = {t for t in edges if t in modules and t != name}
    return graph


def _cycles(graph: dict) -> list:
    """Return the strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_cycle_in_the_package():
    # Lazy imports inside functions count too: they only hide a cycle.
    assert _cycles(_import_graph(_modules())) == []


def test_cycle_check_can_fail():
    graph = {'a': {'b'}, 'b': {'c'}, 'c': {'a'}, 'd': {'a'}}
    assert _cycles(graph) == [['a', 'b', 'c']]


def _package(module: str, modules: dict) -> str:
    """Return the package (directory) of a module: itself for a package's __init__."""
    return module if modules[module].name == '__init__.py' else module.rpartition('.')[0]


def _import_froms(name: str, path: Path, modules: dict):
    """Yield (statement, module imported from) of every from-import, relative ones resolved."""
    own = _package(name, modules) if name in modules else name.rpartition('.')[0]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                parts = own.split('.')[:len(own.split('.')) - node.level + 1]
                base = '.'.join(parts + ([node.module] if node.module else []))
            yield node, base


def _private(name: str) -> bool:
    return name.startswith('_') and not name.startswith('__')


def _private_imports(modules: dict) -> list:
    """Private names imported outside the package that defines them, or re-published."""
    bad = []
    for name, path in modules.items():
        privates = set()
        for node, base in _import_froms(name, path, modules):
            if base not in modules:
                continue
            for alias in node.names:
                if _private(alias.name) and f'{base}.{alias.name}' not in modules:
                    privates.add(alias.asname or alias.name)
                    if _package(base, modules) != _package(name, modules):
                        bad.append(f'{name} imports {base}.{alias.name}')
        # A public alias of an imported private name publishes it a second time.
        for node in ast.parse(path.read_text(), str(path)).body:
            if isinstance(node, ast.Assign) and isinstance(node.value, ast.Name) and \
                    node.value.id in privates:
                bad += [f'{name} publishes {node.value.id} as {t.id}' for t in node.targets
                        if isinstance(t, ast.Name) and not _private(t.id)]
    return bad


def test_no_private_name_imported_outside_its_package():
    # A name with a leading underscore belongs to the package (directory) that defines
    # it; a name used beyond it is public in its one home, with a docstring.
    bad = _private_imports(_modules())
    assert not bad, '\n'.join(bad)


def test_private_check_can_fail(tmp_path):
    root = tmp_path / 'imu_allan'
    (root / 'a').mkdir(parents=True)
    (root / 'b').mkdir()
    files = {'imu_allan.a': 'a/__init__.py', 'imu_allan.a.x': 'a/x.py',
             'imu_allan.a.y': 'a/y.py', 'imu_allan.b': 'b/__init__.py',
             'imu_allan.b.z': 'b/z.py'}
    text = {'a/x.py': 'def _f():\n    pass\n',
            'a/y.py': 'from .x import _f\nf = _f\n',
            'b/z.py': 'from ..a.x import _f\n'}
    modules = {}
    for module, rel in files.items():
        (root / rel).write_text(text.get(rel, ''))
        modules[module] = root / rel
    assert _private_imports(modules) == ['imu_allan.a.y publishes _f as f',
                                         'imu_allan.b.z imports imu_allan.a.x._f']


def _top_statements(body: list):
    for node in body:
        yield node
        for field in ('body', 'orelse', 'finalbody'):
            if isinstance(node, (ast.If, ast.Try)):
                yield from _top_statements(getattr(node, field, []))
        if isinstance(node, ast.Try):
            for handler in node.handlers:
                yield from _top_statements(handler.body)


def _defined(path: Path) -> set:
    """Names a module binds itself at top level (def, class, assignment), not by import."""
    out = set()
    for node in _top_statements(ast.parse(path.read_text(), str(path)).body):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            out.update(n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name))
    return out


def _exported(path: Path) -> set:
    """Return a package's ``__all__`` (its public API), empty when it has none."""
    for node in ast.parse(path.read_text(), str(path)).body:
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == '__all__' for t in node.targets):
            return set(ast.literal_eval(node.value))
    return set()


def _second_paths(files: dict, modules: dict, api: bool) -> list:
    """
    Return the imports of a name from a module that does not define it (a second path).

    ``files`` maps the importing module's dotted name to its path.  With ``api``, a
    package's ``__init__`` that lists the name in ``__all__`` is a valid path too.
    """
    defined = {m: _defined(p) for m, p in modules.items()}
    bad = []
    for name, path in files.items():
        for node, base in _import_froms(name, path, modules):
            if base not in modules:
                continue
            for alias in node.names:
                if f'{base}.{alias.name}' in modules or alias.name in defined[base]:
                    continue
                if api and modules[base].name == '__init__.py' and \
                        alias.name in _exported(modules[base]):
                    continue
                bad.append(f'{path.name}:{node.lineno} imports {alias.name} from {base}, '
                           'which does not define it')
    return bad


def test_one_import_path_per_name():
    # Inside the package a name is imported from the module that defines it, never
    # through a module that imports it; tests and benchmarks may also use a package's
    # public API (its __all__).
    modules = _modules()
    bad = _second_paths(modules, modules, api=False)
    outside = {f'{d}.{p.stem}': p for d in ('test', 'bench') for p in (REPO / d).glob('*.py')}
    bad += _second_paths(outside, modules, api=True)
    assert not bad, '\n'.join(bad)


def test_second_path_check_can_fail(tmp_path):
    root = tmp_path / 'imu_allan'
    root.mkdir()
    (root / '__init__.py').write_text("from .x import F\n__all__ = ['F']\n")
    (root / 'x.py').write_text('F = 1\n')
    (root / 'y.py').write_text('from imu_allan.x import F\n')
    (root / 'z.py').write_text('from imu_allan.y import F\nfrom imu_allan import F\n')
    modules = {'imu_allan': root / '__init__.py', 'imu_allan.x': root / 'x.py',
               'imu_allan.y': root / 'y.py', 'imu_allan.z': root / 'z.py'}
    strict = _second_paths({'imu_allan.z': root / 'z.py'}, modules, api=False)
    assert [b.split(' imports ')[0] for b in strict] == ['z.py:1', 'z.py:2']
    assert len(_second_paths({'t.z': root / 'z.py'}, modules, api=True)) == 1


#: A class longer than this many lines says why in a comment right above it.
LONG_CLASS_LINES = 150


def _long_classes_without_why(path: Path) -> list:
    lines = path.read_text().split('\n')
    bad = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ClassDef) and \
                node.end_lineno - node.lineno + 1 > LONG_CLASS_LINES:
            first = min([node.lineno] + [d.lineno for d in node.decorator_list])
            if first < 2 or not lines[first - 2].lstrip().startswith('#'):
                bad.append(f'{path.name}: {node.name}')
    return bad


def test_every_long_class_says_why():
    bad = [b for path in sorted(PKG.rglob('*.py')) for b in _long_classes_without_why(path)]
    assert not bad, bad


def test_long_class_check_can_fail(tmp_path):
    body = '    x = 1\n' * LONG_CLASS_LINES
    src = tmp_path / 'c.py'
    src.write_text(f'class A:\n{body}\n\n# Long because ...\n@dataclass\nclass B:\n{body}\n'
                   f'class C:\n    x = 1\n')
    assert _long_classes_without_why(src) == ['c.py: A']


#: Most lines a module may have; a longer one is split along a seam (a part with its own
#: state or its own job), not cut in two.
MAX_MODULE_LINES = 500
#: Modules still over it while they are being split (issue 36).
LONG_MODULES: set = set()


def _long_modules(root: Path, limit: int, allowed: set) -> list:
    """Return the modules below ``root`` with more than ``limit`` lines, less ``allowed``."""
    return [f'{rel}: {n} lines' for path in sorted(root.rglob('*.py'))
            if (rel := str(path.relative_to(root))) not in allowed
            and (n := len(path.read_text().splitlines())) > limit]


def test_no_module_over_500_lines():
    bad = _long_modules(PKG, MAX_MODULE_LINES, LONG_MODULES)
    assert not bad, bad


def test_long_module_check_can_fail(tmp_path):
    (tmp_path / 'a').mkdir()
    (tmp_path / 'a' / 'long.py').write_text('x = 1\n' * 11)
    (tmp_path / 'short.py').write_text('x = 1\n' * 10)
    assert _long_modules(tmp_path, 10, set()) == ['a/long.py: 11 lines']
    assert _long_modules(tmp_path, 10, {'a/long.py'}) == []


#: Test files named by a topic that spans modules, not by the module they test.
TEST_TOPICS = {
    'colcon': 'the colcon build and install', 'docs': 'links, paths and names in docs/',
    'flake8': 'lint', 'mypy': 'types', 'pep257': 'docstrings', 'layers': 'this file',
    'gate': "the session's input checks together (clock, spikes, motion)",
    'fuzz_readers': 'every reader on damaged files', 'launch': 'launch/imu_allan.launch.py',
    'package_xml': 'package.xml', 'paper': "the reference paper's numbers",
    'realdata': 'the real recordings end to end', 'registry': 'a toy term through the package',
    'robustness': 'degraded records against the clean one (bench/metamorphic.py)',
    'speed_paths': 'no compiled code, no timing in comments, one BLAS thread',
    'unusual': 'valid-but-unusual inputs against their truth (bench/unusual_campaign.py)',
}


def _unmirrored(test_names: list, module_names: set) -> list:
    """Return the test files named neither test_<module>[_<aspect>].py nor by a topic."""
    return [t for t in test_names if t not in TEST_TOPICS and not any(
        t == m or t.startswith(m + '_') for m in module_names)]


def test_test_files_mirror_the_source():
    # test_<module or subpackage>[_<aspect>].py (test_fit.py for core/fit/, test_cli_adev.py
    # for cli/adev.py), or a topic of TEST_TOPICS.
    names = {part for m in _modules() for part in m.split('.')[1:]}
    tests = sorted(p.stem[len('test_'):] for p in (REPO / 'test').glob('test_*.py'))
    assert not _unmirrored(tests, names)
    assert set(TEST_TOPICS) <= set(tests), 'a topic without its test file'


def test_mirror_check_can_fail():
    assert _unmirrored(['fit', 'cli_adev', 'docs', 'fitting', 'misc'], {'fit', 'cli'}) == \
        ['fitting', 'misc']


def _skips_own_modules(path: Path) -> list:
    """Return the project modules a test file imports through pytest.importorskip."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Call) and getattr(node.func, 'attr', '') == 'importorskip' \
                and node.args and isinstance(node.args[0], ast.Constant) \
                and str(node.args[0].value).split('.')[0] == 'imu_allan':
            out.append(node.args[0].value)
    return out


def test_no_test_skips_over_its_own_package():
    # Only optional extras may be missing; a project module that fails to import is a
    # failure, not a skip.
    bad = {p.name: _skips_own_modules(p) for p in sorted((REPO / 'test').glob('*.py'))}
    assert not {k: v for k, v in bad.items() if v}


def test_skip_check_can_fail(tmp_path):
    src = tmp_path / 't.py'
    src.write_text("import pytest\nm = pytest.importorskip('imu_allan.io.csv_io')\n"
                   "c = pytest.importorskip('cv2')\n")
    assert _skips_own_modules(src) == ['imu_allan.io.csv_io']
