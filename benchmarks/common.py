"""Helpers shared by the benchmarks: machine description, median timing, doc output.

Nothing here is timed itself; the benchmarks import it so that every report states the
machine in the same words. Colour errors come from ``precompute.colour.colour_difference``.
"""

from __future__ import annotations

import functools
import importlib
import os
import pathlib
import platform
import statistics
import time
from collections.abc import Callable

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: The add-on's GPU layer, module by module (addon/gpu/).
GPU_MODULES = ("context", "layout", "shaders", "resources", "mesh", "draw")


def gpu_layer(package: str):
    """``<package>.addon.gpu`` of the extension imported under the id ``package``, with its modules
    imported (``layer.draw.draw_items``, ``layer.resources.TableTexture``, …)."""
    for name in GPU_MODULES:
        importlib.import_module(f"{package}.addon.gpu.{name}")
    return importlib.import_module(f"{package}.addon.gpu")


# ----------------------------------------------------------------------------------------------
# Machine
# ----------------------------------------------------------------------------------------------
def cpu_model() -> str:
    """CPU model name from /proc/cpuinfo (Linux), else ``platform.processor()``."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as handle:
            for line in handle:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def cpu_details() -> str:
    """Family/model numbers and the widest SIMD the kernel reports (from /proc/cpuinfo)."""
    fields, flags = {}, set()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as handle:
            for line in handle:
                key, _, value = line.partition(":")
                key = key.strip()
                if key in ("cpu family", "model", "stepping", "cache size") and key not in fields:
                    fields[key] = value.strip()
                elif key == "flags" and not flags:
                    flags = set(value.split())
    except OSError:
        return "n/a"
    simd = [f for f in ("avx2", "fma", "avx512f", "avx512_bf16", "amx_tile") if f in flags]
    parts = [f"family {fields.get('cpu family', '?')} model {fields.get('model', '?')}"]
    if "cache size" in fields:
        parts.append(f"cache {fields['cache size']}")
    parts.append("SIMD " + ("/".join(simd) if simd else "none above SSE"))
    return ", ".join(parts)


def usable_cores() -> int:
    """Cores this process may run on (affinity), falling back to ``os.cpu_count()``."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def blas_info() -> str:
    """numpy's BLAS as numpy reports it (name, version, OpenBLAS build configuration)."""
    try:
        config = np.show_config(mode="dicts")
        blas = config["Build Dependencies"]["blas"]
        text = f"{blas.get('name', '?')} {blas.get('version', '')}".strip()
        if blas.get("openblas configuration"):
            text += f" ({blas['openblas configuration']})"
        return text
    except Exception as exc:  # noqa: BLE001 — informational only
        return f"unknown ({exc})"


def thread_env() -> str:
    """Thread-count environment variables that affect BLAS (unset ones are omitted)."""
    names = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
    found = [f"{n}={os.environ[n]}" for n in names if n in os.environ]
    return ", ".join(found) if found else "none set (BLAS uses all usable cores)"


def machine_lines() -> list[str]:
    """Markdown bullet lines describing the machine and the numerical stack."""
    return [
        f"- CPU: {cpu_model()} ({cpu_details()})",
        f"- Cores: {usable_cores()} usable ({os.cpu_count()} logical reported by the OS); "
        f"{platform.system()} {platform.release()} {platform.machine()}",
        f"- Python {platform.python_version()}, numpy {np.__version__}",
        f"- BLAS: {blas_info()}",
        f"- Code: {code_version()}",
        f"- Thread variables: {thread_env()}",
        f"- Load average (1, 5, 15 min) at the start of the run: {START_LOAD}; at the end: {load_average()}.",
        "  The machine is shared, so absolute times are noisy: compare rows of one run, not runs.",
    ]


def code_version() -> str:
    """Git commit of the repository and whether ``precompute/`` differs from it (at import time)."""
    return CODE_VERSION


def git_describe(paths=("precompute",)) -> str:
    """``git <commit> <date>`` and whether ``paths`` (folders of the repository) differ from it."""
    import subprocess

    try:
        head = subprocess.run(
            ["git", "log", "-1", "--format=%h %cI"], cwd=ROOT, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--", *paths], cwd=ROOT, capture_output=True, text=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "not a git checkout"
    names = " ".join(f"{p}/" for p in paths)
    if dirty:
        return f"git {head} ({names} {'has' if len(paths) == 1 else 'have'} uncommitted changes or new files)"
    return f"git {head}, {names} clean"


@functools.cache
def source_digest(paths=("addon", "precompute", "glsl")) -> str:
    """A digest of the product's source as it is on disk (every .py, .glsl and .toml under
    ``paths``, committed or not) when first asked, read once per run like :data:`CODE_VERSION`:
    a cache of the product's own output keyed by it is recomputed after any change to the code."""
    import hashlib

    digest = hashlib.sha256()
    for folder in paths:
        for path in sorted(pathlib.Path(ROOT, folder).rglob("*")):
            if path.suffix in (".py", ".glsl", ".toml") and "__pycache__" not in path.parts:
                digest.update(str(path.relative_to(ROOT)).encode())
                digest.update(path.read_bytes())
    return digest.hexdigest()


#: Recorded when the benchmark starts, so the report names the code that was measured.
CODE_VERSION = git_describe()


def load_average() -> str:
    """The 1, 5 and 15 minute load averages, formatted."""
    try:
        return ", ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


#: Load average when the benchmark process imported this module.
START_LOAD = load_average()


# ----------------------------------------------------------------------------------------------
# Timing
# ----------------------------------------------------------------------------------------------
def time_once(func: Callable[[], object]) -> tuple[float, object]:
    """(seconds, result) of one call, ``time.perf_counter``."""
    start = time.perf_counter()
    out = func()
    return time.perf_counter() - start, out


def time_once_cpu(func: Callable[[], object]) -> tuple[float, float, object]:
    """(wall seconds, process CPU seconds over all threads, result) of one call.

    CPU time is much less sensitive than wall time to other processes on a shared machine
    (it still includes any busy-waiting of BLAS threads).
    """
    wall, cpu = time.perf_counter(), time.process_time()
    out = func()
    return time.perf_counter() - wall, time.process_time() - cpu, out


def time_runs(func: Callable[[], object], runs: int = 7, warmup: int = 1) -> list[float]:
    """Wall times of ``runs`` calls after ``warmup`` untimed calls."""
    for _ in range(warmup):
        func()
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return times


def median_time(func: Callable[[], object], runs: int = 7, warmup: int = 1) -> float:
    """Median wall time of ``runs`` calls after ``warmup`` untimed calls."""
    return statistics.median(time_runs(func, runs, warmup))


def fmt_seconds(seconds: float) -> str:
    """Human-scaled time: µs, ms or s with 3 significant figures."""
    if seconds < 1e-3:
        return f"{seconds * 1e6:.3g} µs"
    if seconds < 1.0:
        return f"{seconds * 1e3:.3g} ms"
    return f"{seconds:.3g} s"


def fmt_rate(per_second: float) -> str:
    """Evaluations per second as M/s or k/s."""
    if per_second >= 1e6:
        return f"{per_second / 1e6:.2f} M/s"
    return f"{per_second / 1e3:.1f} k/s"


# ----------------------------------------------------------------------------------------------
# Bake caches (benchmarks clear them to time cold bakes; nothing in precompute/ is modified)
# ----------------------------------------------------------------------------------------------
def clear_bake_caches() -> None:
    """Forget what a new material or roughness must compute: the microfacet/diffuse kernels, the
    GGX albedo, the SH order's lobe (and the u-degree hint, in bakers that keep one)."""
    from precompute.bakes import bake, kernel

    kernel.microfacet_kernel.cache_clear()
    kernel.diffuse_kernel.cache_clear()
    bake.brdf.ggx_E.cache_clear()
    bake.brdf.ggx_E_avg.cache_clear()
    getattr(bake, "_DEGREE_HINT", {}).clear()
    try:
        from precompute.bakes import sh_order
    except ImportError:  # a baker from before the order table
        return
    sh_order._band_energies.cache_clear()


# ----------------------------------------------------------------------------------------------
# Output
# ----------------------------------------------------------------------------------------------
def write_doc(name: str, text: str) -> str:
    """Write ``docs/<name>`` and return its path."""
    path = os.path.join(ROOT, "docs", name)
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(text if text.endswith("\n") else text + "\n")
    return path
