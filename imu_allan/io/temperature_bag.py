"""
The temperature of a bag: a ``sensor_msgs/msg/Temperature`` topic, read whole.

A temperature topic is slow (a few messages per second) and small beside the Imu
topic, so it is read once, before the Imu stream, through rosbags' reader
(``AnyReader``: rosbag2 directories, sqlite3 or MCAP, and ROS 1 bags), and handed to
the session as ``(header.stamp [ns], temperature [degC])``
(:meth:`imu_allan.pipeline.session.Session.add_temperature`), which interpolates it
at each IMU stamp.  Which topic: the one named (``--temperature-topic``), else the
bag's only Temperature topic (said in a note); none, and the analysis is the one
without a temperature.
"""

from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from imu_allan.errors import InputError

#: The message types read as a temperature.
TEMPERATURE_MSGTYPES = ('sensor_msgs/msg/Temperature', 'sensor_msgs/Temperature')


class BagTemperature(NamedTuple):
    """
    The temperature topic read from a bag.

    Attributes
    ----------
    topic : str
        The topic read.
    stamp_ns : np.ndarray
        Shape (n,), header stamps [ns] (int64), in stamp order.
    temp_c : np.ndarray
        Shape (n,), temperatures [degC].
    note : str
        What was chosen, for the user ('' when the topic was named).

    """

    topic: str
    stamp_ns: np.ndarray
    temp_c: np.ndarray
    note: str = ''


def read_temperature(path, topic: str | None = None) -> BagTemperature | None:
    """
    Read a bag's temperature topic (module docstring).

    Parameters
    ----------
    path : str or Path
        The bag (what :func:`imu_allan.io.bag_reader.open_imu` opens).
    topic : str, optional
        The Temperature topic; by default the bag's only one.

    Returns
    -------
    BagTemperature or None
        None when no topic is named and the bag has no Temperature topic.

    Raises
    ------
    InputError
        The named topic is missing or not a Temperature; several Temperature topics and
        none named; the bag cannot be read by rosbags.

    """
    from rosbags.highlevel import AnyReader

    path = Path(path)
    try:
        reader = AnyReader([path])
        reader.open()
    except Exception as err:  # noqa: B902 - a library failure becomes one line
        if topic is None:
            return None
        raise InputError(f'{path}: cannot read the temperature topic {topic} '
                         f'({type(err).__name__}: {err})') from None
    try:
        found = {c.topic: c for c in reader.connections if c.msgtype in TEMPERATURE_MSGTYPES}
        note = ''
        if topic is not None:
            wanted = topic if topic.startswith('/') else '/' + topic
            name = next((t for t in (topic, wanted) if t in found), None)
            if name is None:
                others = {c.topic: c.msgtype for c in reader.connections}
                what = (f'is {others.get(topic) or others.get(wanted)}, not '
                        'sensor_msgs/msg/Temperature' if topic in others or wanted in others
                        else 'is not in the bag')
                raise InputError(f'{path}: temperature topic {topic} {what}; Temperature '
                                 f'topics: {", ".join(sorted(found)) or "none"}')
        elif not found:
            return None
        elif len(found) > 1:
            raise InputError(f'{path}: {len(found)} Temperature topics '
                             f'({", ".join(sorted(found))}): choose one with '
                             '--temperature-topic')
        else:
            name = next(iter(found))
            note = f"the temperature is read from {name}, the bag's only Temperature topic"
        conns = [c for c in reader.connections if c.topic == name
                 and c.msgtype in TEMPERATURE_MSGTYPES]
        stamps, values = [], []
        for conn, _recv_ns, raw in reader.messages(connections=conns):
            msg: Any = reader.deserialize(raw, conn.msgtype)
            stamps.append(int(msg.header.stamp.sec) * 1_000_000_000
                          + int(msg.header.stamp.nanosec))
            values.append(float(msg.temperature))
    except InputError:
        raise
    except Exception as err:  # noqa: B902 - a damaged message, a library failure
        raise InputError(f'{path}: cannot read the temperature topic '
                         f'({type(err).__name__}: {err})') from None
    finally:
        reader.close()
    t = np.asarray(stamps, dtype=np.int64)
    order = np.argsort(t, kind='stable')
    return BagTemperature(name, t[order], np.asarray(values, dtype=np.float64)[order], note)
