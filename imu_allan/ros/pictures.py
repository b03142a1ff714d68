"""
The node's Allan deviation as a picture on ``~/adev_image`` (sensor_msgs/Image).

So that a user sees the curve build in rqt_image_view or Foxglove: the measured curve
with its 95 % band from the first minutes, the fitted models once there are fits.  A
picture is drawn only while someone subscribes, at most every
``adev_image_period_s``, in a thread of its own (matplotlib, imported on first use;
without it the topic stays silent and the node says so once).
"""

import threading

from sensor_msgs.msg import Image

#: The picture's size [pixel]: two panels (gyro, accelerometer) side by side.
WIDTH_PX, HEIGHT_PX = 1040, 416


class CurvePictures:
    """
    Draw and publish the curve pictures of one node.

    Parameters
    ----------
    publisher : rclpy.publisher.Publisher
        The sensor_msgs/Image publisher of ``~/adev_image``.
    logger : object
        Has ``warning`` taking one string.

    """

    def __init__(self, publisher, logger):
        self.publisher = publisher
        self.log = logger
        self._thread: threading.Thread | None = None
        self._off = False

    def wanted(self) -> bool:
        """Tell whether a picture is due: someone subscribes and none is being drawn."""
        return (not self._off and self.publisher.get_subscription_count() > 0
                and (self._thread is None or not self._thread.is_alive()))

    def draw(self, view, result, topic: str, stamp) -> None:
        """
        Draw the picture of a session view in the background and publish it.

        Parameters
        ----------
        view : imu_allan.ros.live.SessionView
            The data so far.
        result : imu_allan.pipeline.analysis.AnalysisResult or None
            The latest fit, whose models are drawn over the curve (None: curve only).
        topic : str
            The analysed topic, for the title.
        stamp : builtin_interfaces.msg.Time
            The header stamp.

        """
        self._thread = threading.Thread(target=self._draw, args=(view, result, topic, stamp),
                                        name='imu_allan_picture', daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop drawing; wait for a picture being drawn (none is published after this)."""
        self._off = True
        if self._thread is not None:
            self._thread.join()

    def _draw(self, view, result, topic: str, stamp) -> None:
        curve = view.curve()
        if curve is None:
            return
        try:
            from imu_allan.io.plot import adev_rgb
        except ImportError as exc:
            self._off = True
            self.log.warning(f'~/adev_image stays silent: {exc} (pip install matplotlib)')
            return
        state = (f'models fitted to {result.duration_s / 3600:.2f} h' if result is not None
                 else 'no fit yet')
        title = (f'Allan deviation of {topic}: {view.duration_s / 3600:.2f} h, '
                 f'{view.stats.n_used:,} still samples at {view.rate_hz:.1f} Hz ({state})')
        pixels = adev_rgb(curve, result.fits if result is not None else {}, title,
                          WIDTH_PX, HEIGHT_PX)
        msg = Image(height=pixels.shape[0], width=pixels.shape[1], encoding='rgb8',
                    is_bigendian=0, step=pixels.shape[1] * 3, data=pixels.tobytes())
        msg.header.stamp = stamp
        if not self._off:       # closed while drawing: the node is going
            self.publisher.publish(msg)
