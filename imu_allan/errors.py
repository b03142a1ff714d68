"""User-facing error types shared by every layer."""


class InputError(ValueError):
    """
    Bad input that the user can fix: the message is one clear line, shown as is.

    The CLI prints it as ``imu-allan: error: <message>`` and exits with code 2; the
    node logs it and keeps the data it already has.
    """


class NotEnoughStillData(InputError):
    """
    Too little still data remains to analyse (the IMU moved most of the time).

    ``imu-allan analyze`` ends with exit code 3 (:attr:`exit_code`) instead of writing
    consumer files; the node keeps collecting and says so in its status.
    """

    exit_code = 3
