"""The gait step queue of section 8.2: legs waiting to step, with push, pop and swap.

Unlike the fixed gait step sequence S of section 8.1, the queue changes while planning:
a leg that stepped goes to the back (push); a leg whose step failed changes places with
the next one (swap), so it is retried right after another leg has moved instead of a whole
gait cycle later (section 8.2, comment ii). After several failures in a row the failed leg
goes farther back, so that every leg gets its turn before any is retried.
"""

from __future__ import annotations

from collections import deque

from planner.core.legs import LEG_NAMES

CRAWL = (2, 0, 3, 1)  # HL, FL, HR, FR: the quasi-static crawl (0-based legs)


class GaitQueue:
    """A queue of 0-based leg indices."""

    def __init__(self, legs=CRAWL):
        legs = [int(i) for i in legs]
        if not legs or any(i not in range(4) for i in legs):
            raise ValueError(f"gait queue: legs must be 0..3, got {legs!r}")
        self._q: deque[int] = deque(legs)

    def pop(self) -> int:
        """Take the leg at the front."""
        if not self._q:
            raise IndexError("gait queue is empty")
        return self._q.popleft()

    def push(self, leg: int) -> None:
        """Put a leg at the back (it has stepped)."""
        self._q.append(int(leg))

    def swap(self, leg: int, depth: int = 1) -> None:
        """Reinsert a leg that failed ``depth`` places back: the next legs go first.

        Pass the number of failures in a row as ``depth``: with plain swaps (depth 1) two
        legs that both cannot step (their support triangles are slivers) would trade
        places for ever while a third leg, which could step and widen them, never comes.
        """
        depth = max(1, min(int(depth), len(self._q)))
        self._q.insert(depth, int(leg))

    def __len__(self) -> int:
        return len(self._q)

    def __iter__(self):
        return iter(list(self._q))

    def __repr__(self) -> str:
        return "GaitQueue([" + ", ".join(LEG_NAMES[i] for i in self._q) + "])"
