"""Bake progress: how far apart in time a bake's progress reports (its cancellation points) are.

Usage (from the repository root)::

    .venv/bin/python -m benchmarks.bake_progress        # → docs/bake-progress.md

Issue 20 asks that progress move in steps of ≤ 10 % and that Esc cancel within 0.5 s. A bake
is cancelled at its next progress report (:mod:`precompute.bakes.progress`), so the wait is at most
the longest gap between two reports. For each preset at its default quality, cold (kernel
caches cleared) and warm, this records the number of reports, the longest gap in wall-clock
seconds and in CPU seconds of the process (all threads: the work itself, which the machine's
load does not stretch) and the largest step of the fraction.
"""

from __future__ import annotations

import time

import numpy as np

from precompute.bakes import bake
from precompute.materials.material import PRESETS

from . import common


def measure(name: str) -> dict:
    """One bake of preset ``name``: reports, total and longest gap (s), largest step."""
    stamps, cpu, fractions, texts = [], [], [], []
    start, start_cpu = time.perf_counter(), time.process_time()

    def report(fraction, text):
        stamps.append(time.perf_counter())
        cpu.append(time.process_time())
        fractions.append(fraction)
        texts.append(text)

    bake.bake(PRESETS[name], progress=report)
    gaps = np.diff([start, *stamps])
    cpu_gaps = np.diff([start_cpu, *cpu])
    steps = np.diff([0.0, *fractions])
    return {
        "reports": len(stamps),
        "total_s": stamps[-1] - start,
        "max_gap_s": float(gaps.max()),
        "max_cpu_gap_s": float(cpu_gaps.max()),
        "max_step": float(steps.max()),
        "gap_phase": (["start", *texts])[int(gaps.argmax())],
    }


def main() -> int:
    """Measure every preset cold and warm and write docs/bake-progress.md."""
    rows = []
    for name in PRESETS:
        common.clear_bake_caches()
        cold = measure(name)
        warm = measure(name)
        rows.append((name, cold, warm))
        print(name, cold, warm)
    worst = max(max(c["max_gap_s"], w["max_gap_s"]) for _, c, w in rows)
    worst_cpu = max(max(c["max_cpu_gap_s"], w["max_cpu_gap_s"]) for _, c, w in rows)
    lines = [
        "# Bake progress and cancellation",
        "",
        "Written by `benchmarks/bake_progress.py`. A bake is cancelled at its next progress report,",
        "so Esc waits at most the longest gap between two reports. Default quality of every preset.",
        "",
        "| Preset | Bake | Reports | Total (s) | Longest gap (s) | in phase | Longest gap (CPU s) "
        "| Largest step |",
        "|---|---|---:|---:|---:|---|---:|---:|",
    ]
    for name, cold, warm in rows:
        for kind, r in (("cold", cold), ("warm", warm)):
            lines.append(
                f"| {name} | {kind} | {r['reports']} | {r['total_s']:.2f} | {r['max_gap_s']:.3f} | "
                f"{r['gap_phase']} | {r['max_cpu_gap_s']:.3f} | "
                f"{100 * r['max_step']:.1f} % |"
            )
    lines += [
        "",
        f"Longest gap over all bakes: **{worst:.3f} s** wall clock, **{worst_cpu:.3f} CPU s** "
        "(the issue's bound: 0.5 s). On a shared machine the wall-clock gap stretches with the "
        "load average (each process gets a share of the 2 cores); the CPU seconds are the step's "
        "own work, spread over BLAS's threads on an idle machine.",
        "",
    ]
    lines += ["## Machine", ""]
    lines += common.machine_lines()
    print(common.write_doc("bake-progress.md", "\n".join(lines)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
