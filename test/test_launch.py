"""
launch/imu_allan.launch.py, checked structurally (and launched when launch_ros exists).

``launch`` and ``launch_ros`` are not on PyPI, so here the launch file is parsed with
ast, not executed: the package, executable, parameter file and remapping it names are
checked against setup.py, config/ and the node's subscription.  Where launch_ros is
importable (a sourced ROS 2 install), the launch description is also generated.
"""

import ast
import importlib.util

import pytest

from conftest import REPO

LAUNCH = REPO / 'launch' / 'imu_allan.launch.py'


def _node_call() -> ast.Call:
    tree = ast.parse(LAUNCH.read_text())
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call)
             and getattr(n.func, 'id', None) == 'Node']
    assert len(calls) == 1
    return calls[0]


def _kw(call: ast.Call, name: str):
    return next(k.value for k in call.keywords if k.arg == name)


def test_launch_file_names_the_installed_executable_and_package():
    call = _node_call()
    assert ast.literal_eval(_kw(call, 'package')) == 'imu_allan'
    executable = ast.literal_eval(_kw(call, 'executable'))
    setup = ast.parse((REPO / 'setup.py').read_text())
    scripts = [ast.literal_eval(n) for n in ast.walk(setup)
               if isinstance(n, ast.Constant) and isinstance(n.value, str) and ' = ' in n.value]
    assert f'{executable} = imu_allan.ros.node:main' in scripts
    assert ast.literal_eval(_kw(call, 'name')) == 'imu_allan'


def test_launch_file_uses_the_installed_config_and_remaps_the_node_input():
    text = LAUNCH.read_text()
    assert "'config', 'imu_allan.yaml'" in text and (REPO / 'config' / 'imu_allan.yaml').is_file()
    setup = (REPO / 'setup.py').read_text()
    assert "glob('config/*.yaml')" in setup and "glob('launch/*.launch.py')" in setup
    remaps = _kw(_node_call(), 'remappings')
    (pair,) = remaps.elts
    assert ast.literal_eval(pair.elts[0]) == 'imu'          # the node subscribes to 'imu'
    node_src = (REPO / 'imu_allan' / 'ros' / 'node.py').read_text()
    assert "Imu, 'imu', self._on_imu" in node_src
    # The arguments are (name, default, description) tuples fed to DeclareLaunchArgument.
    table = next(n.value for n in ast.walk(ast.parse(text)) if isinstance(n, ast.Assign)
                 and getattr(n.targets[0], 'id', None) == 'arguments')
    declared = {ast.literal_eval(t.elts[0]) for t in table.elts}
    used = {ast.literal_eval(n.args[0]) for n in ast.walk(ast.parse(text))
            if isinstance(n, ast.Call) and getattr(n.func, 'id', None) == 'LaunchConfiguration'}
    assert used <= declared
    assert {'imu_topic', 'params_file', 'namespace', 'use_sim_time', 'resume',
            'log_level'} <= declared
    assert 'DeclareLaunchArgument(name, default_value=default' in text


@pytest.mark.skipif(importlib.util.find_spec('launch_ros') is None,
                    reason='launch_ros is not on PyPI: needs a sourced ROS 2 Jazzy install')
def test_launch_description_generates():
    spec = importlib.util.spec_from_file_location('imu_allan_launch', LAUNCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.generate_launch_description().entities
