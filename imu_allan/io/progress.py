"""The one-line progress indicator of the offline commands, on stderr."""

import sys
import threading
import time


class Progress:
    """
    A one-line progress indicator on stderr, shown only when the work takes a while.

    A daemon thread redraws the line (in place on a terminal, a new line every
    ``log_interval_s`` otherwise), so slow steps without their own counter (the fit,
    the plots) still show that work goes on.  Nothing is written to stdout.

    Parameters
    ----------
    label : str
        What is being worked on (a file name).
    total : int or None
        Messages expected (None: unknown).

    """

    #: Seconds before anything is shown.
    delay_s = 2.0
    #: Redraw period on a terminal, and line period otherwise [s].
    tty_interval_s = 0.2
    log_interval_s = 5.0

    def __init__(self, label: str, total: int | None = None, unit: str = 'messages'):
        self.label, self.total, self.unit = label, total, unit
        self.stage = 'reading'
        self.done = 0
        self.start = time.monotonic()
        self.tty = sys.stderr.isatty()
        self.shown = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def update(self, done: int, stage: str | None = None) -> None:
        """Record progress: items done so far, and optionally a new stage name."""
        self.done = done
        if stage is not None:
            self.stage = stage

    def set_stage(self, stage: str) -> None:
        """Name the current step (e.g. 'fitting', 'writing plots')."""
        self.stage = stage

    def line(self) -> str:
        """Return the current progress text."""
        elapsed = time.monotonic() - self.start
        if self.stage == 'reading':
            pct = (f'{100.0 * self.done / self.total:5.1f}% ' if self.total else '')
            text = f'reading {self.label}: {pct}{self.done:,} {self.unit}'
            if elapsed > 0:
                text += f', {self.done / elapsed / 1e6:.2f} M/s'
        elif self.stage == 'analysed':
            text = f'analysed {self.done} of {self.total} {self.unit}'
        else:
            text = f'{self.stage} {self.label}'
        return f'imu-allan: {text} ({elapsed:.0f} s)'

    def _draw(self) -> None:
        text = self.line()
        if self.tty:
            print('\r' + text.ljust(79), end='', file=sys.stderr, flush=True)
        else:
            print(text, file=sys.stderr, flush=True)
        self.shown = True

    def _loop(self) -> None:
        if self._stop.wait(self.delay_s):
            return
        interval = self.tty_interval_s if self.tty else self.log_interval_s
        while True:
            self._draw()
            if self._stop.wait(interval):
                return

    def close(self) -> None:
        """Stop redrawing; end the terminal line."""
        self._stop.set()
        self._thread.join()
        if self.tty and self.shown:
            print(file=sys.stderr, flush=True)

    def __enter__(self) -> 'Progress':
        return self

    def __exit__(self, *exc) -> None:
        self.close()
