"""Progress and cancellation points inside long computations (the bake).

The slow loops of the bake (a reflectance sweep in chunks, one view angle of the microfacet
kernel, one view cosine of the GGX albedo, one block of thickness rows of the contraction) call
:func:`checkpoint` after each step. Outside a bake it does nothing. Inside
:func:`reporting`, each checkpoint moves the bake's progress on and calls its
``progress(fraction, text)`` callback, which may raise to cancel the bake there: the Blender
bake operator's Esc and the viewport's Cancel do that. A step between two checkpoints is sized
to take ≲ 0.1 s on a loaded two-core machine (benchmarks/bake_progress.py measures the gaps),
so a cancel waits well under 0.5 s.

The hook is per thread (the viewport bakes several materials on worker threads at once), so a
checkpoint in a cached helper (``bake.microfacet_kernel``) reports to the bake that called it.

How the fraction moves (:class:`Phases`): the bake is a few phases with relative weights; a
phase that starts gets its weight's share of what is left, and each checkpoint in it moves
the fraction by that share / the checkpoints it expects. A phase that finds its work cached
makes no checkpoints and its share passes on to the next phases, so the fraction never leaps;
no report moves it by more than :data:`MAX_STEP`.
"""

from __future__ import annotations

import contextlib
import threading

__all__ = ["MAX_STEP", "Phases", "checkpoint", "reporting"]

#: Largest move of the fraction between two reports (the issue asks for steps of ≤ 10 %).
MAX_STEP = 0.05

_LOCAL = threading.local()


def checkpoint() -> None:
    """A point between two steps of the current thread's bake: reports progress there, and a
    cancelled bake stops there (the callback raises). Does nothing outside :func:`reporting`."""
    hook = getattr(_LOCAL, "hook", None)
    if hook is not None:
        hook()


@contextlib.contextmanager
def reporting(hook):
    """Call ``hook()`` at every :func:`checkpoint` of this thread inside the ``with`` block."""
    saved = getattr(_LOCAL, "hook", None)
    _LOCAL.hook = hook
    try:
        yield
    finally:
        _LOCAL.hook = saved


class Phases:
    """The bake's fraction done, from named phases with relative weights.

    ``report(fraction, text)`` is the caller's callback. :meth:`start` opens a phase (it
    reports the phase's text at the current fraction); :meth:`tick` (installed as the
    :func:`checkpoint` hook by :meth:`reporting`) moves the fraction one expected step on,
    never past the phase's share; :meth:`done` reports 1.0. Every report is a cancellation
    point, and no report moves the fraction by more than :data:`MAX_STEP` (a longer move, which
    only the end of a bake whose last phase was cached can make, is reported in steps).
    """

    def __init__(self, report, weights: dict[str, float]):
        """``report(fraction, text)``: the callback; ``weights``: phase name → share, in order."""
        self._report = report
        self._weights = dict(weights)
        self._left = list(self._weights)
        self.fraction = 0.0
        self._lo = 0.0
        self._hi = 0.0
        self._step = 0.0
        self._text = ""
        self.reports = 0

    def _emit(self, fraction: float) -> None:
        while fraction - self.fraction > MAX_STEP:
            self.fraction += MAX_STEP
            self._send()
        self.fraction = max(self.fraction, fraction)
        self._send()

    def _send(self) -> None:
        self.reports += 1
        self._report(self.fraction, self._text)

    def start(self, name: str, text: str, expected: int = 1) -> None:
        """Open phase ``name`` (one of the weights' names, in order), expecting ``expected``
        checkpoints; its share is its weight's part of the fraction still to go."""
        while self._left and self._left[0] != name:
            self._left.pop(0)  # a phase skipped entirely hands its share on
        if not self._left:
            raise ValueError(f"unknown or repeated phase {name!r}")
        total = sum(self._weights[n] for n in self._left)
        share = (1.0 - self.fraction) * self._weights[name] / total
        self._left.pop(0)
        self._lo, self._hi = self.fraction, self.fraction + share
        self._step = min(share / max(int(expected), 1), MAX_STEP)
        self._text = text
        self._send()

    def tick(self) -> None:
        """One checkpoint: the fraction moves one expected step on within the phase."""
        self._emit(min(self.fraction + self._step, self._hi))

    def done(self, text: str = "done") -> None:
        """The bake is finished: report 1.0 (in steps of at most :data:`MAX_STEP`)."""
        self._text = text
        self._emit(1.0)

    @contextlib.contextmanager
    def reporting(self):
        """:func:`reporting` with :meth:`tick` as the hook."""
        with reporting(self.tick):
            yield self
