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


class UnitMistake(InputError):
    """
    The first samples show a unit mistake that one ``--units`` declaration would fix.

    The message names the mistake, the declaration, and how to confirm the values as
    they are; ``imu-allan analyze`` exits with code 2 and writes no consumer file, the
    node logs it as an error and publishes nothing.
    """
