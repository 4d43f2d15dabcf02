"""Waiting on the add-on's worker threads, timers and helper processes in tests.

A test waits on the event it asserts, never on time: :func:`wait_for` polls the asserted state
itself (a thread left ``_running``, a grid is built, a helper's pipe ended) and fails only when
that never happens within :data:`EVENT_TIMEOUT_S`, a deadline no correct run comes near even on
a loaded two-core machine (a tiny table bakes in well under a second there). Where the add-on
exposes an Event, wait on the Event (``event.wait(EVENT_TIMEOUT_S)``) and assert its result.
"""

from __future__ import annotations

import threading
import time

#: Longest wait for an event that a correct run produces in seconds at most: only a hang or a
#: lost wake-up reaches it.
EVENT_TIMEOUT_S = 300.0
#: Between two looks at the polled state.
POLL_S = 0.005


def wait_for(predicate, what: str, timeout: float = EVENT_TIMEOUT_S) -> None:
    """Return once ``predicate()`` is true; fail naming ``what`` if it is not after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"waited {timeout:.0f} s for {what}: it never happened"
        time.sleep(POLL_S)


def viewport_lanes_idle(viewport) -> bool:
    """True when none of the viewport timer's workers runs: bakes, the World's analysis, the
    display LUT (``addon.drawing.viewport``'s lanes). A test that asserts the timer's *last* tick
    waits on this: one tick can start a World or display job beside the bake it waited for."""
    return (
        not viewport.bake_jobs.BAKES.running
        and not viewport.world_job.busy()
        and not viewport.display.baking()
    )


class CueRecorder(threading.Event):
    """A worker's "finished" event that records, at each ``set``, whether the worker was still
    listed as running (``still_running()``).

    The add-on's timers read such an event and the running list without a lock: a worker that
    left the list before setting the event can be seen by a tick as neither running nor
    finished; the tick then stops the timer and the redraw with the worker's result never comes.
    ``seen == [True]`` says the order is the safe one.
    """

    def __init__(self, still_running):
        super().__init__()
        self.still_running = still_running
        self.seen: list[bool] = []

    def set(self):
        self.seen.append(bool(self.still_running()))
        super().set()


class HeldCall:
    """``owner.name`` (a bake, a grid build) held at its start until :meth:`open`, so a test reads
    a worker's running state (busy, header, cancel) while it surely runs, however fast the work
    or slow the test's thread. :attr:`entered` is set when a worker reached it; the work then
    runs as it was (``owner.name`` at construction: another test wrapper too)."""

    def __init__(self, owner, name: str, monkeypatch):
        self.real = getattr(owner, name)
        self.entered = threading.Event()
        self.opened = threading.Event()
        monkeypatch.setattr(owner, name, self)

    def __call__(self, *args, **kwargs):
        self.entered.set()
        assert self.opened.wait(EVENT_TIMEOUT_S), "the held call was never let go"
        return self.real(*args, **kwargs)

    def open(self):
        self.opened.set()


class RedrawLog(list):
    """A stand-in for the viewport's ``_tag_redraw`` that records, at each redraw, how many
    times the watched :class:`CueRecorder` had been set by then.

    The timer tick that starts a job may itself take that job's cue (a quick bake beside a slow
    World read): the redraw that shows the result is then that tick's, not the next one's. A
    test asserts ``log.after_cue()``: the last redraw followed the cue, whichever tick made it.
    """

    def __init__(self, cue: CueRecorder):
        super().__init__()
        self.cue = cue

    def __call__(self):
        self.append(len(self.cue.seen))

    def after_cue(self) -> bool:
        return bool(self) and self[-1] >= 1


#: How long a call checked by :func:`finishes` may take: far above any refusal of bad input (each
#: takes milliseconds, seconds under load) and far below what the regressions it catches take (a
#: 293 s bake on an invalid value, 10^10 channel names, reading /dev/zero, a FIFO never opened).
HANG_DEADLINE_S = 30.0


def finishes(call, seconds: float = HANG_DEADLINE_S):
    """``(result, exception)`` of ``call()`` run in a daemon thread; the test fails if it is still
    running after ``seconds`` (a hang, or a long bake on an invalid value)."""
    box = {}

    def run():
        try:
            box["result"] = call()
        except BaseException as exc:  # noqa: BLE001 - handed back to the test
            box["exc"] = exc

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(seconds)
    assert not thread.is_alive(), (
        f"still running after {seconds:.0f} s: a hang, where bad input must be refused"
    )
    return box.get("result"), box.get("exc")
