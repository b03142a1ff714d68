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
        The target path.

    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f'.{path.name}.', suffix='.tmp')
    try:
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
