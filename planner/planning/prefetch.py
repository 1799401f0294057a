"""Each step's swing overlap searched in a second process while the next step is planned.

Issue 16. The search for where a step's swing may start inside its body move
(:func:`planner.planning.overlap.overlap_step`: merged paths rolled and checked sample by
sample) took about a third of a rough2cm plan's time, and nothing planned after the step
depends on it: the next step starts from the step's own end, which the overlap keeps. So
:class:`OverlapWorker` hands each recorded step to a process forked from the planner (the
same objects, no pickled planner) and collects the answers when the walk's samples are put
together (:class:`planner.planning.driver.Walk`), before the planning time is taken. The answers
are the ones the planner would compute itself (the same code on the same inputs), so a
plan is the same to the bit with or without the worker; where there is no ``fork`` (not
Linux, or inside a daemonic process such as a Dask worker) or the worker dies, the
planner computes the overlaps itself. One step is in the worker at a time; a step traced
back (8.5) before its turn is never sent.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import warnings
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from planner.planning.overlap import OverlapPlanner
    from planner.planning.step import Step

__all__ = ["OverlapWorker"]

_PLANNER: OverlapPlanner | None = None  # the planner a forked worker serves
ENV_OFF = "STRATAWALK_OVERLAP_WORKER"  # "0": no worker in this process (nor its children)
PARENT_LOOK_S = 1.0  # how often an idle worker looks whether the planner's process is alive


def _serve(conn, parent_end, parent_pid: int) -> None:
    """The worker: (key, step) in, (key, ok, overlap or error text) out, until None or EOF.

    It closes its copy of the planner's end of the pipe (else the pipe never reports EOF)
    and ends when the planner's process does: killed with it where Linux can
    (PR_SET_PDEATHSIG), else at its next look (a batch job killed on Ctrl-C left its worker
    blocked on the pipe, and the batch hung).
    """
    from planner.planning.overlap import overlap_step

    parent_end.close()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the planner's to handle
    _die_with_parent()
    while True:
        try:
            while not conn.poll(PARENT_LOOK_S):
                if os.getppid() != parent_pid:
                    return
            msg = conn.recv()
        except (EOFError, OSError):
            return
        if msg is None:
            return
        key, step = msg
        try:
            out = (key, True, overlap_step(_PLANNER, step))
        except Exception as exc:  # reported; the planner then computes it itself
            out = (key, False, f"{type(exc).__name__}: {exc}")
        try:
            conn.send(out)
        except OSError:  # the planner is gone
            return


def _die_with_parent() -> None:
    """Ask Linux to kill this process when its parent dies (best effort)."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


class OverlapWorker:
    """A forked process computing :func:`~planner.planning.overlap.overlap_step` for steps.

    :meth:`submit` a step when it is recorded, :meth:`forget` steps traced back,
    :meth:`finish` and :meth:`wait_for` when a walk's samples are put together,
    :meth:`close` at the end.
    Steps are matched by identity; the answer's states that are the step's own (the body
    path before lift-off, the landing) are the step's objects again.
    """

    def __init__(self, planner: OverlapPlanner):
        global _PLANNER
        ctx = mp.get_context("fork")
        self._conn, child = ctx.Pipe()
        _PLANNER = planner
        try:
            self._proc = ctx.Process(
                target=_serve, args=(child, self._conn, os.getpid()), daemon=True
            )
            self._proc.start()
        finally:
            _PLANNER = None
            child.close()
        self._queue: list[Step] = []  # recorded, not yet sent
        self._busy: Step | None = None  # in the worker
        self.sent = 0
        self.used = 0

    @classmethod
    def start(cls, planner: OverlapPlanner) -> OverlapWorker | None:
        """A worker for ``planner``, or None (no fork; ``ENV_OFF`` set to "0").

        ``ENV_OFF`` is for a caller that already runs a planning process per core.
        """
        if os.environ.get(ENV_OFF, "") == "0" or "fork" not in mp.get_all_start_methods():
            return None
        try:
            return cls(planner)
        except (AssertionError, OSError, ValueError):  # a daemonic parent (Dask), no fork
            return None

    def submit(self, step: Step) -> None:
        """Queue ``step``'s overlap (once; not for a step already timed)."""
        if step.timed or step is self._busy or any(s is step for s in self._queue):
            return
        self._queue.append(step)
        self._pump(block=False)

    def forget(self, steps) -> None:
        """Drop ``steps`` (traced back) from the queue; one in the worker is let run."""
        gone = {id(s) for s in steps}
        self._queue = [s for s in self._queue if id(s) not in gone]

    def finish(self, steps) -> None:
        """Before ``steps`` (a walk's, in order) are timed: hand the worker the last.

        Every other queued step is dropped; the worker, if idle, gets the last untimed
        step, and the caller computes the rest from the front, waiting
        (:meth:`wait_for`) only for the one in the worker.
        """
        self._queue = []
        if self._busy is not None and all(s is not self._busy for s in steps):
            self._pump(block=True)  # a traced-back step: wait it out, its answer unused
        self._pump(block=False)
        if self._busy is None:
            last = next((s for s in reversed(steps) if not s.timed), None)
            if last is not None:
                self._send(last)

    def wait_for(self, step: Step) -> None:
        """If ``step`` is in the worker, wait for its answer (it is then timed)."""
        if self._busy is step:
            self._pump(block=True)

    def close(self) -> None:
        """Stop the worker (a step still in it is dropped)."""
        try:
            self._conn.send(None)
        except (OSError, ValueError):
            pass
        self._conn.close()
        self._proc.join(timeout=1.0)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join()

    # ---- the pipe ----------------------------------------------------------------------
    def _send(self, step: Step) -> None:
        try:
            self._conn.send((id(step), step))
        except (OSError, ValueError):
            self._queue.clear()  # the worker is gone: the planner computes the rest
            return
        except Exception:  # a step that does not pickle (pickled before any byte is sent)
            return  # the planner computes this one
        self._busy = step
        self.sent += 1

    def _pump(self, block: bool) -> None:
        """Take the worker's answer if there is one (or wait for it), send the next step."""
        if self._busy is not None and (block or self._conn.poll()):
            try:
                key, ok, got = self._conn.recv()
            except (EOFError, OSError):
                self._busy, self._queue = None, []
                return
            step, self._busy = self._busy, None
            if key == id(step) and ok and not step.timed:
                step.overlap, step.timed = _as_own(step, got), True
                self.used += 1
            elif not ok:
                warnings.warn(f"overlap worker: {got}; computed in the planner", stacklevel=2)
        if self._busy is None and self._queue:
            self._send(self._queue.pop(0))


def _as_own(step: Step, overlap):
    """``overlap`` with the step's own states where it holds copies of them."""
    if overlap is None:
        return None
    states = list(overlap.states)
    lift = overlap.lift
    states[: lift + 1] = step.body_path[: lift + 1]
    states[-1] = step.end
    overlap.states = states
    return overlap
