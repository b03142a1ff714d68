"""User-facing error types shared by every layer."""


class InputError(ValueError):
    """
    Bad input that the user can fix: the message is one clear line, shown as is.

    The CLI prints it as ``imu-allan: error: <message>`` and exits with code 2; the
    node logs it and keeps the data it already has.
    """
