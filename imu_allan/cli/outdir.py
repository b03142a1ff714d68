"""
The output directory of a command, checked before the work and guarded while written.

:func:`prepare_out_dir` refuses, in one line and before any input is read, an ``--out``
that is a file, sits under a file, cannot be created or written (permissions, a
read-only file system) or lacks the space for the outputs; :func:`writing` turns an
``OSError`` while the outputs are written (disk full, read-only) into the same kind of
line, so neither ends in a traceback.
"""

from contextlib import contextmanager
import os
from pathlib import Path
import shutil
import tempfile
from typing import Iterator

from imu_allan.errors import InputError

#: Space kept free for the outputs of one input [bytes]: result.json, eight YAML and
#: text files and two figures take about 0.4 MB (a 90 s, 100 Hz record; the tau grid,
#: hence the files, grows only with the log of the duration); five times that.
OUT_BYTES_PER_INPUT = 2 * 2 ** 20


def prepare_out_dir(out: Path, n_inputs: int = 1) -> bool:
    """
    Check that the outputs can be written to ``out``; create it.

    Parameters
    ----------
    out : Path
        The ``--out`` directory (it may not exist yet).
    n_inputs : int
        Inputs whose outputs go there (the space needed scales with it).

    Returns
    -------
    bool
        True when the directory was created here (see :func:`remove_if_unused`).

    Raises
    ------
    InputError
        ``out`` is a file or under one, cannot be created or written, or has less
        free space than :data:`OUT_BYTES_PER_INPUT` per input.

    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f'--out {out}: exists and is not a directory')
    parent = out
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise InputError(f'--out {out}: {parent} is a file, not a directory')
    created = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
        # A file really written and removed: permissions, a read-only mount and root's
        # privileges all answer as they will for the outputs.
        fd, probe = tempfile.mkstemp(dir=out, prefix='.imu-allan-probe-')
        os.close(fd)
        os.unlink(probe)
        free = shutil.disk_usage(out).free
    except OSError as exc:
        raise InputError(f'--out {out}: cannot write there ({exc.strerror or exc})') from None
    need = OUT_BYTES_PER_INPUT * max(n_inputs, 1)
    if free < need:
        remove_if_unused(out, created)
        raise InputError(f'--out {out}: {free / 2 ** 20:.1f} MiB free, the outputs need '
                         f'about {need / 2 ** 20:.0f} MiB')
    return created


def remove_if_unused(out: Path, created: bool) -> None:
    """Remove ``out`` if this command created it and nothing was written there."""
    if created:
        try:
            Path(out).rmdir()
        except OSError:
            pass


@contextmanager
def writing(out: Path) -> Iterator[None]:
    """Turn an OSError raised while writing outputs to ``out`` into a one-line InputError."""
    try:
        yield
    except OSError as exc:
        raise InputError(f'cannot write the outputs to {out}: '
                         f'{exc.strerror or exc}') from None
