"""The prepared data on disk: OUTDIR/manifest.json + OUTDIR/arrays.npz (+ sources.json).

numpy only: ``measure`` reads it on the GPU machine.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from .config import FORMAT_VERSION, SHUFFLE_BYTES


def digest(array: np.ndarray) -> str:
    a = np.ascontiguousarray(array)
    return hashlib.sha256(a.dtype.str.encode() + str(a.shape).encode() + a.tobytes()).hexdigest()


class ArrayStore:
    """Arrays keyed by their content, each distinct array stored once.

    Arrays over :data:`SHUFFLE_BYTES` of 4-byte items are stored losslessly as the byte planes of
    the differences of neighbouring values' bit patterns (channels first, along the last spatial
    axis, modulo 2³²): smooth float data then compresses about 1.6× better than as is. 4-D arrays
    (texture arrays and 3-D textures) are stored slice by slice, so the slices two textures share
    (the prefiltered World with and without lamps: the levels below the lamp level) are stored once.
    """

    def __init__(self):
        self.arrays: dict[str, np.ndarray] = {}
        self.composite: dict[str, dict] = {}

    def add(self, array, dtype=np.float32) -> str:
        a = np.ascontiguousarray(np.asarray(array, dtype=dtype))
        key = "a" + digest(a)[:16]
        if a.ndim == 4 and a.nbytes > SHUFFLE_BYTES:
            if key not in self.composite:
                slices = [self.add(a[i], dtype) for i in range(a.shape[0])]
                self.composite[key] = {
                    "shape": list(a.shape),
                    "dtype": a.dtype.str,
                    "sha256": digest(a),
                    "slices": slices,
                }
            return key
        self.arrays.setdefault(key, a)
        return key

    def get(self, key: str) -> np.ndarray:
        if key in self.composite:
            return np.stack([self.arrays[k] for k in self.composite[key]["slices"]])
        return self.arrays[key]

    def save(self, path: Path) -> dict:
        """Write ``arrays.npz``; returns the manifest's ``arrays``: {key: {shape, dtype, sha256,
        encoding | slices}}."""
        payload, meta = {}, dict(self.composite)
        for key, a in self.arrays.items():
            delta = a.nbytes > SHUFFLE_BYTES and a.dtype.itemsize == 4
            payload[key] = _delta_encode(a) if delta else a
            meta[key] = {
                "shape": list(a.shape),
                "dtype": a.dtype.str,
                "sha256": digest(a),
                "encoding": "delta" if delta else "raw",
            }
        np.savez_compressed(path, **payload)
        return meta


def _planes_shape(shape) -> tuple:
    return (shape[-1], *shape[:-1]) if len(shape) >= 2 else (1, *shape)


def _delta_encode(a: np.ndarray) -> np.ndarray:
    """(4, n) uint8: byte planes of the bit-pattern differences along the last spatial axis."""
    u = a.view(np.uint32)
    planes = np.moveaxis(u, -1, 0) if a.ndim >= 2 else u[None]
    d = np.ascontiguousarray(planes).copy()
    d[..., 1:] -= planes[..., :-1]  # modulo 2**32
    return np.ascontiguousarray(d.reshape(-1).view(np.uint8).reshape(-1, 4).T)


def _delta_decode(raw: np.ndarray, shape, dtype) -> np.ndarray:
    d = np.ascontiguousarray(raw.T).view(np.uint32).reshape(_planes_shape(shape))
    planes = np.cumsum(d, axis=-1, dtype=np.uint32)  # modulo 2**32, the inverse of the differences
    u = np.moveaxis(planes, 0, -1) if len(shape) >= 2 else planes[0]
    return np.ascontiguousarray(u).view(np.dtype(dtype)).reshape(shape)


class Prepared:
    """A prepared OUTDIR: the manifest, sources and arrays (loaded lazily, checked by hash)."""

    def __init__(self, outdir):
        self.dir = Path(outdir)
        self.manifest = json.loads((self.dir / "manifest.json").read_text(encoding="utf-8"))
        if self.manifest.get("format") != FORMAT_VERSION:
            raise ValueError(f"{outdir}: format {self.manifest.get('format')}, expected {FORMAT_VERSION}")
        self.sources = json.loads((self.dir / "sources.json").read_text(encoding="utf-8"))
        self._npz = np.load(self.dir / "arrays.npz")
        self._cache: dict[str, np.ndarray] = {}

    def array(self, key: str) -> np.ndarray:
        if key not in self._cache:
            meta = self.manifest["arrays"][key]
            if "slices" in meta:
                a = np.stack([self.array(k) for k in meta["slices"]])
            elif meta["encoding"] == "delta":
                a = _delta_decode(self._npz[key], meta["shape"], meta["dtype"])
            else:
                a = self._npz[key]
            if digest(a) != meta["sha256"]:
                raise ValueError(f"array {key}: content does not match its hash")
            self._cache[key] = a
        return self._cache[key]

    def mesh(self, key: str) -> dict:
        """(V, 6|7) float32 interleaved vertices (pos, nor[, thickness]) and (F, 3) int32 indices,
        as ``MeshBatch.from_arrays`` received them (checked against their hashes)."""
        meta = self.manifest["meshes"][key]
        distinct = self.array(meta["distinct"])
        corners = self.array(meta["corners"])
        vertices = distinct[corners]
        indices = self.array(meta["indices"])
        pos, nor = np.ascontiguousarray(vertices[:, :3]), np.ascontiguousarray(vertices[:, 3:6])
        if digest(pos) != meta["sha256"]["positions"] or digest(nor) != meta["sha256"]["normals"]:
            raise ValueError(f"mesh {key}: rebuilt vertices differ from the recorded ones")
        if digest(indices) != meta["sha256"]["indices"]:
            raise ValueError(f"mesh {key}: indices differ from the recorded ones")
        return {**meta, "vertices": np.ascontiguousarray(vertices), "indices": indices}

    def cases(self, scene: str | None = None) -> list[dict]:
        return [c for c in self.manifest["cases"] if scene is None or c["scene"] == scene]
