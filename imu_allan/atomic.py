"""
One way to write a file so that a crash never leaves half of it.

Used by every layer (the accumulator's state, the session's checkpoint, the report
files): write to a temporary file in the same folder, flush it to disk, then rename it
over the target (``os.replace`` is atomic on POSIX and Windows).
"""

import os
from pathlib import Path
import tempfile
from typing import Callable, IO

# The process's umask, read once at import (os.umask sets it while reading it): a file
# written here gets the mode a plain open() would give it, not mkstemp's 0600.
_UMASK = os.umask(0o022)
os.umask(_UMASK)


def write_atomic(path, write: Callable[[IO], object], mode: str = 'wb') -> Path:
    """
    Write a file through a temporary sibling and an atomic rename.

    Parameters
    ----------
    path : str or Path
        Target file; its folder must exist.
    write : callable
        ``write(f)`` fills the open temporary file (its return value is ignored).
    mode : str
        'wb' or 'w'.

    Returns
    -------
    Path
        The target path, with the mode it had, or else the one a plain ``open()`` gives
        (0666 less the umask: readable by the consumers of a report).

    """
    path = Path(path)
    try:
        file_mode = path.stat().st_mode & 0o7777
    except OSError:
        file_mode = 0o666 & ~_UMASK
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f'.{path.name}.', suffix='.tmp')
    try:
        os.fchmod(fd, file_mode)
        with os.fdopen(fd, mode) as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
    return path
