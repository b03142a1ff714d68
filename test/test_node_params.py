"""The parameter table drives config/imu_allan.yaml and the table in docs/node.md."""

import yaml

from conftest import REPO
from imu_allan.ros.params import BY_NAME, config_yaml, markdown_table, PARAMS, session_config


def test_config_file_is_generated_from_the_table():
    text = (REPO / 'config' / 'imu_allan.yaml').read_text()
    assert text == config_yaml(), 'regenerate: python -m imu_allan.ros.params yaml'
    values = yaml.safe_load(text)['/**']['ros__parameters']
    assert set(values) == set(BY_NAME)
    for p in PARAMS:
        assert values[p.name] == p.default
        assert p.check(p.default) is None, p.name


def test_docs_table_is_generated_from_the_table():
    assert markdown_table() in (REPO / 'docs' / 'node.md').read_text(), \
        'regenerate: python -m imu_allan.ros.params markdown'


def test_checks_refuse_bad_values_with_a_reason():
    assert 'outside' in BY_NAME['min_duration_s'].check(0.0)
    assert 'must be float' in BY_NAME['min_duration_s'].check('long')
    assert 'one of' in BY_NAME['on_motion'].check('panic')
    assert 'must be int' in BY_NAME['qos_depth'].check(True)
    assert BY_NAME['min_duration_s'].check(600) is None   # an int for a float is fine


def test_session_config_takes_the_matching_values():
    cfg = session_config({'on_motion': 'restart', 'motion_gyro_rad_s': 0.2,
                          'publish_period_s': 3.0})
    assert cfg.on_motion == 'restart' and cfg.motion_gyro_rad_s == 0.2
    # The sample gate's settings (spikes, motion on the sensor's own noise scale, the
    # still-data floor) are node parameters too, with the pipeline's defaults.
    gate = ('spike_sigma', 'max_spike_share', 'motion_sigma', 'anchor_s', 'min_still_share',
            'min_still_s')
    defaults = session_config({})
    for name in gate:
        assert BY_NAME[name].default == getattr(defaults, name), name
    cfg = session_config({'spike_sigma': 0.0, 'min_still_share': 0.5, 'anchor_s': 30.0})
    assert (cfg.spike_sigma, cfg.min_still_share, cfg.anchor_s) == (0.0, 0.5, 30.0)
