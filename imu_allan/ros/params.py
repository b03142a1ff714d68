"""
The node's parameters: one table for declaration, validation, config YAML and docs.

No ROS import here: the node turns each row into a declared parameter with a
descriptor and range; ``python -m imu_allan.ros.params yaml|markdown`` prints the
config file and the table of docs/node.md from the same rows (a test keeps them in sync).
"""

from dataclasses import dataclass
import os
from pathlib import Path
import sys

from imu_allan.core.allan.raw import RAW_ROWS
from imu_allan.core.plan.targets import DEFAULT_PROFILE, parse_targets, PROFILES
from imu_allan.errors import InputError
from imu_allan.pipeline.hygiene import MOTION_POLICIES, SessionConfig


@dataclass(frozen=True)
class NodeParam:
    """
    One node parameter.

    Attributes
    ----------
    name : str
        Parameter name.
    value_type : type
        bool, int, float or str.
    default : object
        Default value.
    unit : str
        Unit ('' for none).
    limits : tuple
        (low, high) for numbers, the allowed strings for str, () for bool.
    description : str
        What it does, one line.

    """

    name: str
    value_type: type
    default: object
    unit: str
    limits: tuple
    description: str

    def check(self, value) -> str | None:
        """Return why ``value`` is refused, or None when it is valid."""
        if self.value_type is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        wrong_int = self.value_type is int and isinstance(value, bool)
        if not isinstance(value, self.value_type) or wrong_int:
            return f'{self.name} must be {self.value_type.__name__}, got {type(value).__name__}'
        if self.value_type in (int, float) and self.limits:
            lo, hi = self.limits
            if not lo <= value <= hi:
                return f'{self.name} = {value} is outside [{lo}, {hi}] {self.unit}'.rstrip()
        if self.value_type is str and self.limits and value not in self.limits:
            return f'{self.name} must be one of {", ".join(self.limits)}, got {value!r}'
        if self.name == 'plan_targets':
            try:
                parse_targets(value)
            except InputError as exc:
                return f'{self.name}: {exc}'
        return None


_S = SessionConfig()
#: Old parameter names still read for one release (the node warns to rename them): the
#: plan's 'pinned' (every target met) is now 'met', as 'pinned' is a fit's time at an end
#: of its search range.
RENAMED = {'stop_when_pinned': 'stop_when_met'}

PARAMS: tuple[NodeParam, ...] = (
    NodeParam('rate_hz', float, _S.rate_hz, 'Hz', (0.0, 100000.0),
              'Nominal IMU rate; 0 estimates it from the first stamps'),
    NodeParam('min_duration_s', float, 3600.0, 's', (1.0, 1.0e6),
              'Recording length before results are published'),
    NodeParam('stop_when_met', bool, False, '', (),
              'Stop collecting once every axis meets every target of plan_profile '
              '(min_duration_s stays a floor)'),
    NodeParam('plan_profile', str, DEFAULT_PROFILE, '', tuple(PROFILES),
              'Precision targets by use: vio (= kalibr) N +-10 %, K +-50 %; ekf N +-10 %,'
              ' B and K +-25 %; full N, B +-10 %, every other term +-25 %'),
    NodeParam('plan_targets', str, '', '', (),
              "Targets over the profile's, as relative 95 % half-widths, e.g. "
              "'N=0.05,K=25%,B=none'; '' keeps the profile's"),
    NodeParam('plan_period_s', float, 300.0, 's', (0.0, 86400.0),
              'Period of the precision plan (a few fits of CPU), the first after'
              ' min(60 s, one period), also before min_duration_s; 0 never plans'),
    NodeParam('publish_period_s', float, 30.0, 's', (0.1, 86400.0),
              'Period of the fit and of the result topics once min_duration_s is reached'),
    NodeParam('process_period_s', float, 0.2, 's', (0.005, 10.0),
              'Period of the timer that moves buffered messages into the pipeline'),
    NodeParam('progress_period_s', float, 10.0, 's', (0.1, 3600.0),
              'Period of progress reports before min_duration_s'),
    NodeParam('adev_image_period_s', float, 60.0, 's', (0.0, 86400.0),
              'Period of the curve picture on ~/adev_image, drawn only while someone'
              ' subscribes (matplotlib); 0 never draws'),
    NodeParam('qos_depth', int, 10000, 'messages', (1, 1000000),
              'Depth of the Imu subscription queue: 10 s at 1 kHz while ~/save runs'),
    NodeParam('qos_reliability', str, 'best_effort', '', ('best_effort', 'reliable'),
              'Reliability of the Imu subscription (sensor-data QoS is best effort)'),
    NodeParam('max_buffer_messages', int, 1000000, 'messages', (100, 100000000),
              'Messages held between timer ticks; beyond it the oldest are dropped and counted'),
    NodeParam('output_dir', str, '', '', (),
              "Where ~/save, shutdown and checkpoints write their files; '' is"
              ' $ROS_HOME/imu_allan/<namespace>/<node name> (ROS_HOME defaults to ~/.ros),'
              ' one per node'),
    NodeParam('checkpoint_period_s', float, 60.0, 's', (0.0, 86400.0),
              'Period of the atomic accumulator checkpoint; 0 disables it'),
    NodeParam('resume', bool, False, '', (),
              'Continue from the checkpoint in output_dir when rate and axes match'),
    NodeParam('publish_imu_with_covariance', bool, False, '', (),
              'Republish each Imu message on ~/imu_with_covariance with the fitted covariances'),
    NodeParam('initial_covariance_file', str, '', '', (),
              'result.json or imu_covariance.yaml of an earlier run: ~/imu_with_covariance'
              " starts from its covariances ('' starts from a large variance)"),
    NodeParam('diagnose_raw_samples', int, RAW_ROWS, 'samples', (0, 16777216),
              'Rows kept for the effect search and ~/diagnose periodogram (pairs averaged'
              ' as the record grows; 48 bytes each; the default is that of imu-allan'
              ' analyze, so both give the same model); 0 keeps none'),
    NodeParam('gyro_range_rad_s', float, _S.gyro_range_rad_s, 'rad/s', (0.0, 1.0e4),
              'Gyro full scale for the saturation check; 0 disables it'),
    NodeParam('accel_range_m_s2', float, _S.accel_range_m_s2, 'm/s^2', (0.0, 1.0e5),
              'Accelerometer full scale for the saturation check; 0 disables it'),
    NodeParam('frozen_samples', int, _S.frozen_samples, 'samples', (2, 100000000),
              'Identical consecutive values that mark an axis as frozen'),
    NodeParam('gap_factor', float, _S.gap_factor, 'periods', (1.01, 1000.0),
              'A stamp step longer than this many periods is a gap'),
    NodeParam('max_fill_samples', int, _S.max_fill_samples, 'samples', (0, 1000),
              'A gap that lost at most this many samples is filled (no Allan term at short'
              ' taus uses a fill); a longer one splits the record; 0 splits at every gap'),
    NodeParam('rate_tolerance', float, _S.rate_tolerance, '', (0.001, 1.0),
              'Relative rate change that is reported (and refuses a resume)'),
    NodeParam('spike_sigma', float, _S.spike_sigma, 'sigmas', (0.0, 1.0e6),
              'A sample this many noise sigmas from the median of its neighbours is a spike,'
              ' replaced by interpolation and counted; 0 disables the check'),
    NodeParam('max_spike_share', float, _S.max_spike_share, '', (0.0, 1.0),
              'A larger share of spike samples is no analysis (the status says so)'),
    NodeParam('motion_window_s', float, _S.motion_window_s, 's', (0.05, 60.0),
              'Window of the motion detector (at least 10 samples: longer below 10 Hz)'),
    NodeParam('motion_sigma', float, _S.motion_sigma, 'sigmas', (1.0, 1.0e6),
              'A window mean this many sigmas of a still window mean from the still level'
              ' is motion (on the sensor noise scale)'),
    NodeParam('motion_gyro_rad_s', float, _S.motion_gyro_rad_s, 'rad/s', (1.0e-6, 100.0),
              'Cap of the gyro mean change that counts as motion'),
    NodeParam('motion_accel_m_s2', float, _S.motion_accel_m_s2, 'm/s^2', (1.0e-6, 1000.0),
              'Cap of the accelerometer mean change that counts as motion'),
    NodeParam('motion_std_ratio', float, _S.motion_std_ratio, '', (1.5, 1.0e6),
              'Growth of the window noise that counts as motion (vibration)'),
    NodeParam('on_motion', str, _S.on_motion, '', MOTION_POLICIES,
              'warn keeps the samples, pause drops them until still, restart starts over'),
    NodeParam('settle_s', float, _S.settle_s, 's', (0.0, 3600.0),
              'Stillness needed after motion before samples count again'),
    NodeParam('anchor_s', float, _S.anchor_s, 's', (0.1, 86400.0),
              'A still stretch this long at another level becomes the still reference'
              ' (a robot that moved first, then parked)'),
    NodeParam('min_still_share', float, _S.min_still_share, '', (0.0, 1.0),
              'Less still data than this share of the samples is no analysis; the node says'
              ' so and keeps collecting'),
    NodeParam('min_still_s', float, _S.min_still_s, 's', (0.0, 1.0e6),
              'Less still data than this duration is no analysis'),
    NodeParam('warmup_window_s', float, _S.warmup_window_s, 's', (0.0, 86400.0),
              'Still time held at the start (and after a sensor restart) to find where the'
              ' output settled after power-on; the rows before are left out, with a warning'
              ' (at most 2^20 rows; judged at the latest when min_duration_s is reached);'
              ' 0 holds nothing'),
    NodeParam('covering_tau_max_s', float, 100.0, 's', (1.0, 1.0e6),
              'Longest averaging time the covering white + random-walk pair of the VINS and'
              ' OpenVINS files bounds (from the sample period; a VIO window is seconds)'),
    NodeParam('hardware_id', str, '', '', (),
              "hardware_id of the diagnostic statuses; '' takes the frame_id of the messages"),
    NodeParam('frame_id', str, '', '', (),
              'The IMU analysed, by header.frame_id, when the topic carries several (never'
              " merged); '' takes the first seen; the others are counted, named and dropped"),
    NodeParam('temperature_topic', str, '', '', (),
              'sensor_msgs/Temperature topic of the IMU: the thermal coefficient of each axis and'
              " compensated values (docs/thermal.md); '' analyses without a temperature"),
)

BY_NAME = {p.name: p for p in PARAMS}


def as_declared_type(name: str, value):
    """
    Return a parameter override in its declared type: an integer for a double is a float.

    ``-p min_duration_s:=600`` and ``min_duration_s: 600`` in a parameter file reach the
    node as integers; rclpy refuses an integer for a parameter declared with a float
    default, so the node converts such overrides before it declares (every other value
    is returned unchanged, for rclpy and :meth:`NodeParam.check` to judge).

    Parameters
    ----------
    name : str
        Parameter name.
    value : object
        The override's value.

    Returns
    -------
    object
        ``float(value)`` for an int (not bool) given to a float parameter, else ``value``.

    """
    spec = BY_NAME.get(name)
    if (spec is not None and spec.value_type is float and isinstance(value, int)
            and not isinstance(value, bool)):
        return float(value)
    return value


def default_output_dir(node_name: str, environ=None) -> Path:
    """
    Return the output directory used when output_dir is '': under ROS_HOME.

    Parameters
    ----------
    node_name : str
        The node's fully qualified name without the leading '/' (namespace/name).
    environ : mapping, optional
        The environment (default os.environ).

    Returns
    -------
    Path
        ``$ROS_HOME/imu_allan/<node_name>``, with ROS_HOME defaulting to ~/.ros as for
        the ROS logs.

    """
    env = os.environ if environ is None else environ
    home = env.get('ROS_HOME') or os.path.join('~', '.ros')
    return Path(os.path.expanduser(home)) / 'imu_allan' / node_name


def session_config(values: dict) -> SessionConfig:
    """Build the pipeline settings from node parameter values (name -> value)."""
    keys = set(SessionConfig.__dataclass_fields__) & set(values)
    return SessionConfig(**{k: values[k] for k in keys})


def _yaml_value(value) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, str):
        return f"'{value}'"
    return repr(value)


def config_yaml() -> str:
    """Return config/imu_allan.yaml: every parameter with its unit, range and meaning."""
    lines = ['# imu_allan_node parameters (generated from imu_allan/ros/params.py:',
             '# python -m imu_allan.ros.params yaml > config/imu_allan.yaml)',
             '/**:', '  ros__parameters:']
    for p in PARAMS:
        if p.value_type in (int, float) and p.limits:
            rng = f'[{p.limits[0]}, {p.limits[1]}]'
        elif p.value_type is str and p.limits:
            rng = '{' + ', '.join(p.limits) + '}'
        else:
            rng = ''
        meta = ', '.join(x for x in (p.unit, rng) if x)
        lines.append(f'    # {p.description}' + (f' ({meta})' if meta else ''))
        lines.append(f'    {p.name}: {_yaml_value(p.default)}')
    return '\n'.join(lines) + '\n'


def markdown_table() -> str:
    """Return the parameter table of docs/node.md."""
    rows = ['| name | type | default | unit | range | description |',
            '| --- | --- | --- | --- | --- | --- |']
    for p in PARAMS:
        if p.value_type in (int, float) and p.limits:
            rng = f'{p.limits[0]} .. {p.limits[1]}'
        else:
            rng = ', '.join(p.limits)
        rows.append(f'| `{p.name}` | {p.value_type.__name__} | `{_yaml_value(p.default)}` | '
                    f'{p.unit} | {rng} | {p.description} |')
    return '\n'.join(rows) + '\n'


if __name__ == '__main__':
    what = sys.argv[1] if len(sys.argv) > 1 else 'yaml'
    sys.stdout.write(config_yaml() if what == 'yaml' else markdown_table())
