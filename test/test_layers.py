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


def _subpackage(module: str) -> str:
    """imu_allan.core.<sub> inside the core, imu_allan.<layer> elsewhere."""
    parts = module.split('.')
    return '.'.join(parts[:3] if parts[1:2] == ['core'] else parts[:2])


def test_no_private_name_imported_across_subpackages():
    # A name with a leading underscore is its subpackage's own; another one calls a
    # public API instead.
    modules, bad = _modules(), []
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom) and not node.level and node.module and \
                    node.module.startswith('imu_allan'):
                for alias in node.names:
                    private = alias.name.startswith('_') and not alias.name.startswith('__')
                    if private and _subpackage(node.module) != _subpackage(name):
                        bad.append(f'{name} imports {node.module}.{alias.name}')
    assert not bad, '\n'.join(bad)
