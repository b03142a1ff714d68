"""package.xml: every dependency key resolves with rosdep on Ubuntu 24.04 without pip."""

import xml.etree.ElementTree as ET

import yaml

from conftest import REPO

#: Dependency tags rosdep installs from (``rosdep install --from-paths`` takes all).
DEPEND_TAGS = ('depend', 'build_depend', 'buildtool_depend', 'exec_depend', 'test_depend',
               'build_export_depend', 'buildtool_export_depend')


def _keys() -> dict:
    root = ET.parse(REPO / 'package.xml').getroot()
    return {el.text.strip(): el.tag for tag in DEPEND_TAGS for el in root.iter(tag)}


def test_every_key_resolves_for_noble_from_apt_or_a_jazzy_release():
    rules = yaml.safe_load((REPO / 'test' / 'rosdep_noble_keys.yaml').read_text())
    keys = _keys()
    assert 'rclpy' in keys and 'python3-numpy' in keys     # the file was read
    for key, tag in keys.items():
        assert key not in rules['pip_only'], f'{tag} {key} installs only through pip'
        assert key in rules['apt'] or key in rules['jazzy'], \
            f'{tag} {key} is not a rosdep key for noble (ros/rosdistro ' \
            f'{rules["rosdistro_commit"][:8]}); add it to test/rosdep_noble_keys.yaml ' \
            'from rosdep/base.yaml, rosdep/python.yaml or jazzy/distribution.yaml'
    for key, rule in rules['apt'].items():
        assert rule['noble'], f'{key} has no apt package on noble'


def test_the_runtime_and_test_imports_are_declared():
    keys = _keys()
    for key in ('rclpy', 'sensor_msgs', 'std_srvs', 'diagnostic_msgs', 'rcl_interfaces',
                'python3-numpy', 'python3-scipy', 'python3-yaml'):
        assert keys.get(key) == 'exec_depend', key
    for key in ('python3-pytest', 'python3-mypy', 'python3-opencv', 'ament_flake8',
                'ament_pep257'):
        assert keys.get(key) == 'test_depend', key
