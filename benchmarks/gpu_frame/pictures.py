"""Picture comparison in 8-bit levels (numpy only), and pictures saved for a look."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def diff(a: np.ndarray, b: np.ndarray) -> dict:
    """Differences of two RGBA8 pictures in 8-bit levels: over all pixels and channels, and over the
    colour of the pixels both cover (``inside_*``); pixel counts where coverage differs and where a
    colour is off by more than 1 and more than 8 levels."""
    d = np.abs(a.astype(np.int16) - b.astype(np.int16))
    both = (a[..., 3] > 0) & (b[..., 3] > 0)
    inside = d[..., :3][both]
    worst = d[..., :3].max(axis=-1)
    return {
        "max": int(d.max()),
        "mean": float(d.mean()),
        "share_over_1": float(np.mean(d.max(axis=-1) > 1)),
        "share_over_0": float(np.mean(d.max(axis=-1) > 0)),
        "coverage_mismatch_px": int(np.sum((a[..., 3] > 0) != (b[..., 3] > 0))),
        "covered_px": int(both.sum()),
        "inside_max": int(inside.max()) if inside.size else 0,
        "inside_mean": float(inside.mean()) if inside.size else 0.0,
        "over_1_px": int(np.sum(worst > 1)),
        "over_8_px": int(np.sum(worst > 8)),
    }


def compare(result_path, pictures, reference) -> dict:
    """(Re)compute ``vs_check_pictures`` of a result JSON from its pictures (``measure --pictures``)
    and the reference pictures (``check``'s OUTDIR/pictures-check.npz)."""
    res = json.loads(Path(result_path).read_text(encoding="utf-8"))
    with np.load(pictures) as ours, np.load(reference) as ref:
        res["vs_check_pictures"] = {
            name: diff(ours[name], ref[name]) for name in ours.files if name in ref.files
        }
    Path(result_path).write_text(json.dumps(res, indent=1), encoding="utf-8")
    return res["vs_check_pictures"]


def save_picture(path: Path, rgba: np.ndarray) -> Path:
    """``rgba`` as a PNG, or as ``.npy`` where Pillow is missing (the GPU machine may lack it)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        from PIL import Image  # optional: not installed everywhere measure runs
    except ImportError:
        path = path.with_suffix(".npy")
        np.save(path, rgba)
        return path
    Image.fromarray(rgba, "RGBA").save(path)
    return path
