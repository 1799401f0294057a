"""Ctrl-C and SIGTERM for the long commands: stop once, keep what was computed, exit cleanly.

Inside :class:`Interrupts` (the ``plan``, ``batch`` and ``simulate`` commands), the first
SIGINT or SIGTERM stops the work the way Ctrl-C always stopped it: the planner returns the
plan so far, the simulation judges the motion so far, the batch drops its running jobs and
keeps every record written. ``cooperative`` (the default), the signal only sets a flag that
the work polls at safe points (:func:`requested`: the planner between cycles, the simulator
between control ticks, the batch between waits), so it never lands inside a finaliser or a
library callback that would print it and swallow it; otherwise it raises
:class:`KeyboardInterrupt` at once (for work that blocks in a pool's ``map``). Any later
signal only prints that the command is finishing, so a second Ctrl-C cannot cut the
writing of the partial result short (nor leave a pool's workers and threads half shut
down, which hung ``batch``). Code that writes a result runs :func:`shielded`.

Once a signal came, the process ignores further ones after the block (it is ending).
Exit codes, once what was computed is written: 130 after SIGINT, 143 after SIGTERM (128 +
the signal number, the shell's convention); :attr:`Interrupts.exit_code`.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator

__all__ = ["Interrupts", "requested", "shielded"]

_active: list[Interrupts] = []


class Interrupts:
    """Handle SIGINT and SIGTERM in the main thread while the ``with`` block runs."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, cooperative: bool = True) -> None:
        self.cooperative = cooperative
        self.signum: int | None = None  # the first signal received
        self.count = 0
        self._shield = 0
        self._old: dict[int, object] = {}

    def __enter__(self) -> Interrupts:
        if threading.current_thread() is threading.main_thread():
            for s in self.SIGNALS:
                self._old[s] = signal.signal(s, self._handle)
        _active.append(self)
        return self

    def __exit__(self, *exc: object) -> None:
        _active.remove(self)
        if self.interrupted:  # the process is ending: a late signal must not cut its exit short
            for s in self._old:  # (SIG_IGN, unlike a Python handler, outlives finalisation)
                signal.signal(s, signal.SIG_IGN)
            self._old.clear()
            return
        for s, old in self._old.items():
            signal.signal(s, old)
        self._old.clear()

    def _handle(self, signum: int, frame: object) -> None:
        self.count += 1
        if self.signum is None:
            self.signum = signum
        if self.count == 1:
            if self._shield == 0 and not self.cooperative:
                raise KeyboardInterrupt
            return
        print(
            f"\nstratawalk: {signal.Signals(signum).name} again: finishing, writing what was "
            "computed",
            file=sys.stderr,
            flush=True,
        )

    @property
    def interrupted(self) -> bool:
        """A signal arrived."""
        return self.signum is not None

    @property
    def exit_code(self) -> int | None:
        """128 + the first signal's number, or None if none came."""
        return None if self.signum is None else 128 + int(self.signum)

    @contextlib.contextmanager
    def shielded(self) -> Iterator[None]:
        """Signals are noted but do not interrupt the block."""
        self._shield += 1
        try:
            yield
        finally:
            self._shield -= 1


@contextlib.contextmanager
def shielded() -> Iterator[None]:
    """Shield the block from the innermost active :class:`Interrupts` (if any)."""
    if not _active:
        yield
        return
    with _active[-1].shielded():
        yield


def requested() -> bool:
    """A signal asked the innermost active :class:`Interrupts` to stop (poll this)."""
    return bool(_active) and _active[-1].interrupted


def check() -> None:
    """Raise :class:`KeyboardInterrupt` if a stop was :func:`requested` (a safe point)."""
    if requested():
        raise KeyboardInterrupt
