"""
A client of a running node over rclpy: what ``imu-allan node`` does without a ROS install.

The venv has rclpy but no ``ros2`` command line, so this module does what ``ros2 topic
echo`` and ``ros2 service call`` would: read the node's latched topics
(``~/noise_parameters``, ``~/result``) and call its services (``~/save``, ``~/reset``,
``~/diagnose``).  It runs in a context of its own, so it never touches a node in the same
process.
"""

from dataclasses import dataclass
import os
import time

from diagnostic_msgs.msg import DiagnosticArray
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
from std_srvs.srv import Trigger

from imu_allan.errors import InputError

# The node's result topics are latched (transient local), so a late reader gets the last.
_LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL,
                      history=HistoryPolicy.KEEP_LAST)


@dataclass(frozen=True)
class Status:
    """One status of ``~/noise_parameters``: its name, level, message and values."""

    name: str
    level: int
    message: str
    values: dict


class NodeClient:
    """
    Talk to one running imu_allan node.

    Parameters
    ----------
    node_name : str
        The node's fully qualified name (``/imu_allan``, ``/robot1/imu_allan``).
    timeout_s : float
        How long to wait for the node to answer [s].

    """

    def __init__(self, node_name: str = '/imu_allan', timeout_s: float = 10.0):
        self.node_name = '/' + node_name.strip('/')
        self.timeout_s = timeout_s
        self.context = Context()
        rclpy.init(args=[], context=self.context)
        self.node = rclpy.create_node(f'imu_allan_client_{os.getpid()}',
                                      context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def close(self) -> None:
        """Leave the ROS graph."""
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> 'NodeClient':
        """Return the client."""
        return self

    def __exit__(self, *exc) -> None:
        """Close the client."""
        self.close()

    def _absent(self, what: str) -> InputError:
        return InputError(f'no node {self.node_name} answered {what} within '
                          f'{self.timeout_s:g} s: is it running (and in this ROS_DOMAIN_ID)?'
                          ' give its name with --node')

    def call(self, service: str) -> tuple[bool, str]:
        """
        Call one of the node's Trigger services.

        Parameters
        ----------
        service : str
            ``save``, ``reset`` or ``diagnose``.

        Returns
        -------
        tuple of (bool, str)
            The service's success and message.

        Raises
        ------
        InputError
            When the node does not answer within the timeout.

        """
        name = f'{self.node_name}/{service}'
        client = self.node.create_client(Trigger, name)
        if not client.wait_for_service(timeout_sec=self.timeout_s):
            raise self._absent(name)
        future = client.call_async(Trigger.Request())
        # ~/save fits first: it may take much longer than finding the node.
        wait_s = max(self.timeout_s, 600.0)
        self.executor.spin_until_future_complete(future, timeout_sec=wait_s)
        if not future.done() or future.result() is None:
            raise InputError(f'{name} did not answer: the node may be busy or gone')
        response = future.result()
        return bool(response.success), str(response.message)

    def _subscribe(self, topic: str, kind, on_message) -> None:
        self.node.create_subscription(kind, f'{self.node_name}/{topic}', on_message, _LATCHED)

    def latest(self, topic: str, kind):
        """
        Return the last message of a latched topic of the node.

        Parameters
        ----------
        topic : str
            ``noise_parameters`` (DiagnosticArray) or ``result`` (String).
        kind : type
            The message type.

        Returns
        -------
        object
            The message.

        Raises
        ------
        InputError
            When none arrives within the timeout.

        """
        got: list = []
        self._subscribe(topic, kind, got.append)
        end = time.monotonic() + self.timeout_s
        while not got and time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.1)
        if not got:
            what = (f'{self.node_name}/{topic}' + ('' if topic != 'result' else
                    ' (it has no result before min_duration_s of still data)'))
            raise self._absent(what)
        return got[-1]

    def statuses(self) -> list[Status]:
        """Return the latest ``~/noise_parameters`` of the node: progress or results."""
        return as_statuses(self.latest('noise_parameters', DiagnosticArray))

    def result_json(self) -> str:
        """Return the node's latest ``~/result``: the text of its result.json."""
        return self.latest('result', String).data

    def watch(self, on_statuses, until_s: float | None = None) -> None:
        """
        Hand every new ``~/noise_parameters`` to ``on_statuses`` (a list of Status).

        Parameters
        ----------
        on_statuses : callable
            Called with each new list of statuses.
        until_s : float, optional
            Stop after this long [s]; default: until interrupted (Ctrl-C).

        """
        self._subscribe('noise_parameters', DiagnosticArray,
                        lambda msg: on_statuses(as_statuses(msg)))
        end = None if until_s is None else time.monotonic() + until_s
        while end is None or time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.1)


def as_statuses(msg: DiagnosticArray) -> list[Status]:
    """Return the statuses of a DiagnosticArray as plain records."""
    return [Status(s.name, int.from_bytes(s.level, 'little') if isinstance(s.level, bytes)
                   else int(s.level), s.message, {kv.key: kv.value for kv in s.values})
            for s in msg.status]
