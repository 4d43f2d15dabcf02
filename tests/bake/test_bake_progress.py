"""A bake's progress moves in small steps, and a cancelled bake stops at its next checkpoint."""

import threading

import numpy as np
import pytest

from precompute.bakes import bake, chunks, kernel, progress
from precompute.materials.material import PRESETS, Quality

#: Small enough to bake in well under a second, big enough to have every phase.
SMALL = Quality(sh_order=4, view_samples=12, thickness_samples=8, wavelength_count=64)


class Cancelled(Exception):
    """What the test's progress callback raises once cancelled (the add-on raises its own)."""


def _fractions(material):
    seen = []
    bake.bake(material, progress=lambda fraction, text: seen.append(fraction))
    return np.array(seen)


@pytest.mark.parametrize("name", ["soap_film", "beetle_multilayer", "anodised_titanium"])
def test_progress_moves_in_steps_of_at_most_ten_percent_from_zero_to_one(name):
    """Progress moves in steps of at most ten percent from zero to one."""
    fractions = _fractions(PRESETS[name].with_(quality=SMALL))
    steps = np.diff(np.concatenate([[0.0], fractions]))
    assert fractions[-1] == 1.0
    assert steps.min() >= 0.0  # never backwards
    assert steps.max() <= progress.MAX_STEP + 1e-12 <= 0.10  # float rounding of sums
    assert len(fractions) >= 10


def test_a_cached_kernel_hands_its_share_on_without_a_leap():
    """A cached kernel hands its share on without a leap."""
    material = PRESETS["soap_film"].with_(quality=SMALL)
    _fractions(material)  # warms the kernel cache: the kernel phase makes no checkpoints now
    steps = np.diff(np.concatenate([[0.0], _fractions(material)]))
    assert steps.max() <= progress.MAX_STEP + 1e-12


def test_checkpoint_outside_a_bake_does_nothing_and_hooks_are_per_thread():
    """Checkpoint outside a bake does nothing and hooks are per thread."""
    progress.checkpoint()
    calls = []
    with progress.reporting(lambda: calls.append(threading.get_ident())):
        progress.checkpoint()
        other = threading.Thread(target=progress.checkpoint)
        other.start()
        other.join()
    progress.checkpoint()
    assert calls == [threading.get_ident()]


def test_phases_never_exceed_the_largest_step_even_when_a_phase_is_skipped():
    """Phases never exceed the largest step even when a phase is skipped."""
    seen = []
    phases = progress.Phases(lambda f, t: seen.append(f), {"a": 0.5, "b": 0.5})
    phases.start("b", "b", expected=1)  # "a" skipped: its share passes to "b"
    phases.tick()
    phases.done()
    assert np.diff(np.concatenate([[0.0], seen])).max() <= progress.MAX_STEP + 1e-12
    assert seen[-1] == 1.0
    with pytest.raises(ValueError):
        phases.start("a", "again")


def test_the_work_between_two_checkpoints_is_bounded_by_design():
    """Each step's size is a named constant, not the material's: a chunk of a reflectance sweep,
    a block of the contraction, one view angle of the kernel. Bigger tables make more steps."""
    small = chunks.sweep_checkpoints(rows=8, layers=1, nodes=40, wavelengths=64)
    large = chunks.sweep_checkpoints(rows=512, layers=2, nodes=80, wavelengths=1024)
    assert small == 1 and large > 100
    assert chunks.SWEEP_CHUNK <= 250_000 and chunks.CONTRACT_CHUNK <= 50_000_000
    blocks = chunks.row_blocks(512, 9 * 80 * 25 * 90)
    assert all(b.stop - b.start <= max(1, chunks.CONTRACT_CHUNK // (9 * 80 * 25 * 90)) for b in blocks)


@pytest.mark.parametrize("cancel_after", [1, 5, 35])
def test_a_cancelled_bake_stops_at_its_next_checkpoint_and_caches_nothing(cancel_after):
    """The worker is cancelled from another thread after its ``cancel_after``-th report; it must
    stop at the next report (one step later), raise, and leave no kernel in the cache."""
    material = PRESETS["soap_film"].with_(roughness=0.37, quality=SMALL)  # a kernel not cached yet
    kernel.microfacet_kernel.cache_clear()
    cancel = threading.Event()
    reports = {"before": 0, "after": 0}
    outcome = {}

    def report(fraction, text):
        if cancel.is_set():
            reports["after"] += 1
            raise Cancelled
        reports["before"] += 1
        if reports["before"] == cancel_after:
            cancel.set()  # what Esc does, from the main thread: the flag the next report reads

    def worker():
        try:
            bake.bake(material, progress=report)
            outcome["finished"] = True
        except Cancelled:
            outcome["cancelled"] = True

    thread = threading.Thread(target=worker)
    thread.start()
    thread.join(timeout=60)
    assert not thread.is_alive()
    assert outcome == {"cancelled": True}
    assert reports == {"before": cancel_after, "after": 1}  # stopped at the very next checkpoint
    assert kernel.microfacet_kernel.cache_info().currsize == 0 or cancel_after > 30
