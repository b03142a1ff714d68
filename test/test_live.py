"""
The node's input side (imu_allan.ros.live) driven with plain bytes, rclpy refused.

LiveInput holds the buffer, decoding, session, resume and snapshots of the node; these
tests run it in a subprocess whose import machinery refuses rclpy and every ROS message
package, so what they check holds without ROS.
"""

import subprocess
import sys

from conftest import REPO

SCRIPT = r"""
import logging, sys, tempfile
from pathlib import Path

class Refuse:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ('rclpy', 'sensor_msgs', 'std_msgs', 'std_srvs',
                                  'diagnostic_msgs', 'rcl_interfaces'):
            raise ImportError('refused ' + name)
        return None

sys.meta_path.insert(0, Refuse())
import numpy as np
from imu_allan.io.bag_writer import serialize_imu
from imu_allan.ros.live import LiveInput
from imu_allan.pipeline.spikes import CHUNK, CONTEXT
from imu_allan.ros.params import PARAMS

rng = np.random.default_rng(5)
n = 30_000
stamps = 1_700_000_000 * 10 ** 9 + np.arange(n, dtype=np.int64) * 5_000_000   # 200 Hz
samples = rng.standard_normal((n, 6)) * 1e-3
samples[:, 5] += 9.81
rows = serialize_imu(stamps, samples, frame_id='imu_front')
values = {p.name: p.default for p in PARAMS}
with tempfile.TemporaryDirectory() as tmp:
    live = LiveInput(values, Path(tmp), logging.getLogger('live'))
    for k in range(0, n, 1000):             # callbacks, then the timer's hand-over
        for raw in rows[k:k + 1000]:
            live.append(raw.tobytes())
        if live.due():
            live.process()
    live.process()
    view, raw = live.snapshot()
    assert live.n_received == n and live.frame_id == 'imu_front', live.frame_id
    # Held back at most: the spike filter's chunk and context, one motion window.
    assert 0 <= n - view.stats.n_used <= CHUNK + CONTEXT + 200, view.stats
    assert view.curve() is not None and raw is not None
    assert live.checkpoint(flush=True) and live.checkpoint_path.exists()
    resumed = LiveInput(dict(values, resume=True), Path(tmp), logging.getLogger('live'))
    assert resumed.session.stats.n_used == n
    live.reset()
    assert live.session.stats.n_used == 0 and not live.buffer
print('ok')
"""


def test_the_live_input_runs_on_plain_bytes_without_ros():
    out = subprocess.run([sys.executable, '-c', SCRIPT], cwd=REPO, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().endswith('ok')


def test_a_unit_mistake_is_logged_once_and_nothing_is_used(tmp_path):
    import numpy as np

    from imu_allan.io.bag_writer import serialize_imu
    from imu_allan.ros.live import LiveInput
    from imu_allan.ros.params import PARAMS

    class Log:

        def __init__(self):
            self.lines = {'info': [], 'warning': [], 'error': []}

        def __getattr__(self, level):
            return self.lines[level].append

    rng = np.random.default_rng(7)
    n = 3000
    stamps = 1_700_000_000 * 10 ** 9 + np.arange(n, dtype=np.int64) * 10_000_000  # 100 Hz
    samples = rng.standard_normal((n, 6)) * 1e-3
    samples[:, :3] += 0.02          # a MEMS gyro's bias [rad/s]
    samples[:, :3] *= 57.3          # a driver that publishes deg/s
    samples[:, 5] += 9.81
    log = Log()
    live = LiveInput({p.name: p.default for p in PARAMS}, tmp_path, log)
    for k in range(0, n, 100):
        for raw in serialize_imu(stamps[k:k + 100], samples[k:k + 100]):
            live.append(raw.tobytes())
        live.process()
    assert len(log.lines['error']) == 1, log.lines
    assert 'rerun with --units gyro=deg/s' in log.lines['error'][0]
    assert live.session.unit_problem is not None and live.session.stats.n_used == 0
    assert live.snapshot()[0].curve() is None
    live.reset()                    # a new session judges again
    assert live.session.unit_problem is None
