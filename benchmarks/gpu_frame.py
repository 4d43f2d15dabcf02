"""GPU frame time of our draw alone: the extension's shaders and data, drawn through moderngl + EGL.

Usage (from the repository root)::

    .venv/bin/python -m benchmarks.gpu_frame prepare OUTDIR
        # with bpy: the benchmark scenes of benchmarks/viewport.py → OUTDIR (every shader variant,
        # uniform buffer, texture and mesh a frame draws; about 30 MiB)
    .venv/bin/python -m benchmarks.gpu_frame check OUTDIR
        # with bpy: this harness's pictures against gpu_draw.draw_items on the same OpenGL
        # (→ OUTDIR/check.json, OUTDIR/pictures-check.npz); needs moderngl
    python3 -m benchmarks.gpu_frame measure OUTDIR --out RESULT.json [--backend egl]
        [--pictures DIR] [--rounds N] [--skip 'sweep-l12-*' …] [--budget-s S] [--no-blender-sources]
        # numpy + moderngl only (no bpy, no precompute): compile, draw and time every case
    python -m benchmarks.gpu_frame compare RESULT.json DIR/pictures-480x270.npz OUTDIR/pictures-check.npz
        # (re)compute the picture comparison of a result with the llvmpipe pictures of ``check``
    python -m benchmarks.gpu_frame report RESULT.json [--extra MORE.json …]
        # → docs/gpu-frame.md; --extra merges further measure runs (other sizes, a few cases) into
        # docs/gpu-frame.json first, which ``report docs/gpu-frame.json`` then rebuilds from

Why: the viewport benchmark (benchmarks/viewport.py, docs/performance.md) runs inside bpy, and
the only OpenGL here is Mesa's llvmpipe. The GPU machine lent to some tasks cannot run bpy (its
wheel is far over what can be carried there, and it has Python 3.12 only), so ``prepare`` takes
everything a frame of ours needs out of the real extension, and ``measure`` draws it again with
nothing but numpy and moderngl:

- *Shaders*: for every variant that ``gpu_draw.prepare_draw`` picks, the create-info exactly as
  ``gpu_draw._mesh_shader_info`` fills it (recorded by standing in for ``gpu.types``'s create-info
  classes: defines, ``TYPEDEFS``, uniform buffers and samplers with their slots, vertex inputs,
  the interface, the fragment output, the vertex and fragment bodies: ``shading_library`` and the
  chunks). ``measure`` writes the declarations Blender 5.2's OpenGL backend generates from it
  (``#version 430``, the defines, the typedefs, ``layout(binding = N, std140) uniform _name
  { Type name; };``, ``layout(binding = N) uniform sampler…``, ``layout(location = N) in …``,
  the interface block, ``layout(location = 0) out vec4 tf_frag_color``) in front of the bodies.
  Where bpy runs on OpenGL, ``prepare`` also keeps the source Blender itself compiled for each
  variant (read back from the driver), and ``measure`` compiles that too and draws the pictures
  with both: Blender's adds only its GLSL compatibility macros.
- *Data*: uniform buffers and textures as ``gpu_draw`` uploads them (recorded where it creates
  them: lighting, table and film in a uniform buffer or a 2-D array texture, the prefiltered World
  as a 3-D texture), the view and object uniform buffers as ``prepare_draw`` fills them, the draws
  in the order and grouping ``prepare_draw`` gives them, and each mesh as ``MeshBatch.from_arrays``
  receives it (stored as its distinct vertices and the map back, rebuilt bit for bit).
- *Scenes* (benchmarks/viewport.py's, the same World, film and tori): ``sweep``, 10 tori with
  100 k triangles at l = 2, 5, 8, 12, each film as SH only, combined (split sum + SH) and split
  sum only (``viewport.roughness_cases``), with the World's lamps shaded per light direction
  (the product's default) and with the films' "World Lamps" off; ``grid``, 1 torus with 1.00 M
  triangles at l = 4 (SH order 5) and l = 2, SH only, lamps on and off. 1920×1080, the view of
  the scene camera. ``prepare`` runs on llvmpipe, where small tables are read from the uniform
  buffer; cases "<film>-tex" are the same films with the table read from its texture, as a
  hardware GPU draws them (``gpu_draw.TABLE_UBO_DEVICES``), and "sh-loops" (l = 8, 12) the SH
  film with the generic rotation loops instead of the generated X(±90°) code.

``measure`` draws each case as ``gpu_draw.submit`` does: into an RGBA8 framebuffer with a 24-bit
depth buffer, cleared to 0 and depth 1, depth test LEQUAL with writes, no blending, no culling,
display sRGB variants (exposure 0), one bind of each group's resources and one draw call per
object. Textures: RGBA32F; the table and film read with ``texelFetch`` (NEAREST, CLAMP_TO_EDGE:
Blender's default sampler), the prefiltered World LINEAR without mipmaps, REPEAT in u and
CLAMP_TO_EDGE in v and w (``gpu_draw.PrefilterTexture``). Each case: warm-up frames, then
rounds over the cases of one scene in alternating order; per frame the GPU time of a
``GL_TIME_ELAPSED`` query around the clear and the draws, and the wall time from the first call
to the return of ``glFinish``. Medians are reported; a case ``clear`` (the clear alone) is timed
with them. Our draw only: Blender's draw manager, the Workbench pass underneath and the Python
work per frame (``scene_draw.collect``, ``prepare_draw``) are not in it (docs/performance.md
measures those).

``check`` proves that the harness draws what the product draws: the same cases at 480×270
through ``gpu_draw.draw_items`` into a ``GPUOffScreen`` (RGBA8, display sRGB) and through
``measure`` (a subprocess) on the same OpenGL; the 8-bit pictures must agree to 1 level.
``measure`` compares its pictures with ``OUTDIR/pictures-check.npz`` when it is there (the
harness's pictures from ``check``), which gives the difference between the two drivers.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent

#: Frame size of the timed frames and of the pictures that ``check`` compares.
RESOLUTION = (1920, 1080)
CHECK_SIZE = (480, 270)
#: The scenes: (objects, triangles), SH orders, film cases, World lamps (viewport.py's constants
#: are read in ``prepare``; these must agree with them and are checked there).
SCENES = {
    "sweep": {"layout": (10, 100_000), "l_max": (2, 5, 8, 12), "cases": ("sh", "combined", "split")},
    "grid": {"layout": (1, 1_000_000), "l_max": (4, 2), "cases": ("sh",)},
}
LAMPS = (True, False)
#: Scenes and orders whose films are also drawn with the table read from its texture (case
#: "<case>-tex"): what a hardware GPU draws (gpu_draw.TABLE_UBO_DEVICES), since ``prepare`` runs on
#: llvmpipe, which draws small tables from the uniform buffer.
TEXTURE_CASES_SCENES = ("sweep", "grid")
#: Sweep orders whose SH-only film (lamps on, table from the texture) is also drawn with the
#: generic rotation loops of tf_sh_rotate.glsl instead of the generated X(±90°) code (case
#: "sh-loops"; ``gpu_draw.ShaderCache(generated_x90=False)``).
LOOP_CASES_L = (8, 12)
TEXTURE_CASES_L = (2, 4, 5, 8)
#: Warm-up frames per case and timed rounds per scene (every case once a round).
WARMUP = 5
ROUNDS = 40
#: Cases whose full-size picture ``measure --pictures`` writes as PNG (at most this many).
PNG_CASES = ("sweep-l5-sh-lamps", "sweep-l5-combined-lamps", "sweep-l5-split-lamps", "grid-l4-sh-lamps")
#: Arrays above this many bytes are stored as byte planes (compresses float data far better).
SHUFFLE_BYTES = 1 << 20
FORMAT_VERSION = 1
#: The acceptance figure for a GPU (issue: 1080p, 1 M triangles, SH order 5).
FPS_TARGET = 240.0
DOC = "gpu-frame.md"


def case_id(scene: str, l_max: int, case: str, lamps: bool) -> str:
    return f"{scene}-l{l_max}-{case}-{'lamps' if lamps else 'nolamps'}"


# ----------------------------------------------------------------------------------------------
# Storage: OUTDIR/manifest.json + OUTDIR/arrays.npz (+ sources.json)
# ----------------------------------------------------------------------------------------------
def _digest(array: np.ndarray) -> str:
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
        key = "a" + _digest(a)[:16]
        if a.ndim == 4 and a.nbytes > SHUFFLE_BYTES:
            if key not in self.composite:
                slices = [self.add(a[i], dtype) for i in range(a.shape[0])]
                self.composite[key] = {
                    "shape": list(a.shape),
                    "dtype": a.dtype.str,
                    "sha256": _digest(a),
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
                "sha256": _digest(a),
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
            if _digest(a) != meta["sha256"]:
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
        if _digest(pos) != meta["sha256"]["positions"] or _digest(nor) != meta["sha256"]["normals"]:
            raise ValueError(f"mesh {key}: rebuilt vertices differ from the recorded ones")
        if _digest(indices) != meta["sha256"]["indices"]:
            raise ValueError(f"mesh {key}: indices differ from the recorded ones")
        return {**meta, "vertices": np.ascontiguousarray(vertices), "indices": indices}

    def cases(self, scene: str | None = None) -> list[dict]:
        return [c for c in self.manifest["cases"] if scene is None or c["scene"] == scene]


# ----------------------------------------------------------------------------------------------
# prepare (bpy): record what the extension draws
# ----------------------------------------------------------------------------------------------
class _Recorder:
    """Stands in for ``gpu.types.GPUShaderCreateInfo`` / ``GPUStageInterfaceInfo``: records calls."""

    def __init__(self, *args):
        self.args = args
        self.calls: list[tuple[str, tuple]] = []

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        return lambda *args, **kwargs: self.calls.append((name, args, kwargs))


class _Namespace:
    """A module stand-in: the given attributes, everything else from ``base``."""

    def __init__(self, base, **overrides):
        self._base = base
        self.__dict__.update(overrides)

    def __getattr__(self, name):
        return getattr(self._base, name)


#: Create-info calls the harness understands (anything else fails ``prepare`` loudly).
_INFO_CALLS = {
    "define",
    "typedef_source",
    "uniform_buf",
    "sampler",
    "vertex_in",
    "vertex_out",
    "fragment_out",
    "vertex_source",
    "fragment_source",
}


def _create_info_dict(info: _Recorder, iface: _Recorder, sources: dict) -> dict:
    """The recorded create-info as JSON: the order of the calls is kept (it is the order Blender
    declares them in)."""
    out = {
        "defines": [],
        "typedefs": [],
        "resources": [],
        "vertex_in": [],
        "interfaces": [],
        "fragment_out": [],
    }
    for name, args, kwargs in info.calls:
        if name not in _INFO_CALLS or kwargs:
            raise ValueError(
                f"create-info call {name}{args} {kwargs} is not known to benchmarks/gpu_frame.py"
            )
        if name == "define":
            out["defines"].append([args[0], args[1] if len(args) > 1 else ""])
        elif name == "typedef_source":
            out["typedefs"].append(_source_key(sources, args[0]))
        elif name in ("uniform_buf", "sampler"):
            slot, type_name, res = args
            kind = "ubo" if name == "uniform_buf" else "sampler"
            out["resources"].append({"kind": kind, "slot": int(slot), "type": type_name, "name": res})
        elif name == "vertex_in":
            out["vertex_in"].append([int(args[0]), args[1], args[2]])
        elif name == "vertex_out":
            stage = args[0]
            members = []
            for call, margs, mkwargs in stage.calls:
                if call not in ("smooth", "flat", "no_perspective") or mkwargs:
                    raise ValueError(f"interface call {call}{margs} is not known to benchmarks/gpu_frame.py")
                members.append([call, margs[0], margs[1]])
            out["interfaces"].append({"name": stage.args[0], "members": members})
        elif name == "fragment_out":
            out["fragment_out"].append([int(args[0]), args[1], args[2]])
        elif name == "vertex_source":
            out["vertex_source"] = _source_key(sources, args[0])
        elif name == "fragment_source":
            out["fragment_source"] = _source_key(sources, args[0])
    if iface is not None and not any(i["name"] == iface.args[0] for i in out["interfaces"]):
        raise ValueError("the stage interface was made but not used")
    return out


def _source_key(sources: dict, text: str) -> str:
    key = "s" + hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]
    sources.setdefault(key, text)
    return key


class _NamedVariant:
    """A recorded variant under another name (the loop rotation of :class:`Capture`)."""

    def __init__(self, variant, name: str):
        self.variant, self.name = variant, name


def variant_key(variant) -> str:
    """A readable name of a ``gpu_draw.Variant``: l, then the flags that are set."""
    if isinstance(variant, _NamedVariant):
        return variant.name
    flags = [name for name, value in variant._asdict().items() if name != "l_max" and value]
    return "-".join([f"l{variant.l_max}", *flags])


class Capture:
    """Records, while active, what ``gpu_draw`` uploads and compiles, through stand-ins:

    - ``gpu.types.GPUTexture`` / ``GPUUniformBuf`` as seen from gpu_draw: the real object is made
      and returned, its data kept by ``id`` (every table, film, lighting and prefiltered World);
    - ``MeshBatch.from_arrays``: the arrays of each batch, by ``id`` of its GPUBatch;
    - a ``ShaderCache`` whose ``_compile`` records the variant's create-info instead of compiling
      (``_mesh_shader_info`` runs with create-info recorders in place of gpu.types's);
    - a uniform cache whose ``get`` keeps what ``make()`` returns (view and object buffers).
    """

    def __init__(self, gd):
        self.gd = gd
        self.uploads: dict[int, dict] = {}
        self.meshes: dict[int, dict] = {}
        self.keep: list = []  # the recorded GPU objects stay alive, so their ids stay unique
        self.sources: dict[str, str] = {}
        self.variants: dict[str, dict] = {}
        capture = self

        class Shaders(gd.ShaderCache):
            def _compile(self, key, make_info):
                name = variant_key(key)
                if name not in capture.variants:
                    capture.variants[name] = {"variant": key._asdict(), **capture.create_info(make_info)}
                return key

        class Uniforms:
            def next_frame(self):
                pass

            def get(self, key, make):
                return _Uniform(np.asarray(make(), dtype=np.float32).ravel().copy())

        class LoopShaders(gd.ShaderCache):
            """The generic rotation loops (``generated_x90=False``), recorded as "<variant>-loops"."""

            def _compile(self, key, make_info):
                name = variant_key(key) + "-loops"
                if name not in capture.variants:
                    capture.variants[name] = {
                        "variant": key._asdict(),
                        "generated_x90": False,
                        **capture.create_info(make_info),
                    }
                return _NamedVariant(key, name)

        self.shaders = Shaders()
        self.loop_shaders = LoopShaders(generated_x90=False)
        self.uniforms = Uniforms()

    def create_info(self, make_info) -> dict:
        gd = self.gd
        real = gd.gpu
        types = _Namespace(real.types, GPUShaderCreateInfo=_Recorder, GPUStageInterfaceInfo=_Recorder)
        gd.gpu = _Namespace(real, types=types)
        try:
            info, iface = make_info()
        finally:
            gd.gpu = real
        return _create_info_dict(info, iface, self.sources)

    def __enter__(self):
        gd, capture = self.gd, self
        real = gd.gpu

        def texture(*args, **kwargs):
            tex = real.types.GPUTexture(*args, **kwargs)
            size = args[0] if args else kwargs["size"]
            data = kwargs.get("data")
            capture.uploads[id(tex)] = {
                "kind": "texture",
                "size": [int(s) for s in size],
                "layers": int(kwargs.get("layers", 0)),
                "format": kwargs.get("format", "RGBA8"),
                "data": None if data is None else np.array(data, dtype=np.float32).ravel(),
            }
            capture.keep.append(tex)
            return tex

        def uniform_buf(data, *args, **kwargs):
            ubo = real.types.GPUUniformBuf(data, *args, **kwargs)
            capture.uploads[id(ubo)] = {"kind": "ubo", "data": np.array(data, dtype=np.float32).ravel()}
            capture.keep.append(ubo)
            return ubo

        self._real_gpu = real
        gd.gpu = _Namespace(real, types=_Namespace(real.types, GPUTexture=texture, GPUUniformBuf=uniform_buf))
        self._from_arrays = gd.MeshBatch.__dict__["from_arrays"]
        original = self._from_arrays.__func__

        def from_arrays(cls, positions, normals, indices, thickness=None):
            batch = original(cls, positions, normals, indices, thickness)
            if batch is not None:
                capture.meshes[id(batch.batch)] = {
                    "positions": np.ascontiguousarray(np.asarray(positions, dtype=np.float32).reshape(-1, 3)),
                    "normals": np.ascontiguousarray(np.asarray(normals, dtype=np.float32).reshape(-1, 3)),
                    "indices": np.ascontiguousarray(np.asarray(indices).reshape(-1, 3).astype(np.int32)),
                    "thickness": None
                    if thickness is None
                    else np.ascontiguousarray(np.asarray(thickness, dtype=np.float32).reshape(-1)),
                }
                capture.keep.append(batch)
            return batch

        gd.MeshBatch.from_arrays = classmethod(from_arrays)
        return self

    def __exit__(self, *exc):
        self.gd.gpu = self._real_gpu
        self.gd.MeshBatch.from_arrays = self._from_arrays
        return False


class _Uniform:
    """What the recording uniform cache hands to ``prepare_draw`` in place of a GPUUniformBuf."""

    def __init__(self, data: np.ndarray):
        self.data = data


class _Writer:
    """Turns captured draws into the manifest's JSON, arrays into the store (deduplicated)."""

    def __init__(self, capture: Capture):
        self.capture = capture
        self.store = ArrayStore()
        self.meshes: dict[str, dict] = {}
        self._mesh_keys: dict[int, str] = {}

    def upload(self, obj, role: str) -> dict:
        rec = self.capture.uploads.get(id(obj))
        if rec is None:
            raise RuntimeError(f"{role}: made before the capture started (clear scene_draw.CACHES first)")
        if rec["kind"] == "ubo":
            return {"kind": "ubo", "array": self.store.add(rec["data"])}
        size, layers = rec["size"], rec["layers"]
        if rec["format"] != "RGBA32F" or rec["data"] is None:
            raise RuntimeError(f"{role}: texture {rec['format']} without data is not supported")
        if layers:
            shape, dim = (layers, size[1], size[0], 4), "2d_array"
        elif len(size) == 3:
            shape, dim = (size[2], size[1], size[0], 4), "3d"
        else:
            shape, dim = (size[1], size[0], 4), "2d"
        return {"kind": "texture", "dim": dim, "array": self.store.add(rec["data"].reshape(shape))}

    def mesh(self, batch) -> str:
        if id(batch) in self._mesh_keys:
            return self._mesh_keys[id(batch)]
        rec = self.capture.meshes.get(id(batch))
        if rec is None:
            raise RuntimeError("a batch was built before the capture started")
        parts = [rec["positions"], rec["normals"]]
        if rec["thickness"] is not None:
            parts.append(rec["thickness"][:, None])
        vertices = np.concatenate(parts, axis=1).astype(np.float32)
        key = "m" + _digest(vertices)[:8] + _digest(rec["indices"])[:8]
        if key not in self.meshes:
            rows = np.ascontiguousarray(vertices).view(
                np.dtype((np.void, vertices.dtype.itemsize * vertices.shape[1]))
            )
            _, first, inverse = np.unique(rows.ravel(), return_index=True, return_inverse=True)
            order = np.argsort(first)  # distinct vertices in the order of their first corner
            rank = np.empty_like(order)
            rank[order] = np.arange(order.size)
            distinct = vertices[first[order]]
            corners = rank[inverse.ravel()]
            assert np.array_equal(distinct[corners], vertices)
            idx = rec["indices"]
            self.meshes[key] = {
                "distinct": self.store.add(distinct),
                "corners": self.store.add(corners, np.int32),
                "indices": self.store.add(idx, np.int32),
                "vertex_count": int(vertices.shape[0]),
                "triangle_count": int(idx.shape[0]),
                "thickness": rec["thickness"] is not None,
                # Blender's GPUIndexBuf keeps 16-bit indices when the range (and the restart index) fits
                "index_bits": 16
                if int(idx.max()) - int(idx.min()) + 1 <= 0xFFFF and int(idx.min()) == 0
                else 32,
                "sha256": {
                    "positions": _digest(rec["positions"]),
                    "normals": _digest(rec["normals"]),
                    "indices": _digest(idx),
                },
            }
        self._mesh_keys[id(batch)] = key
        return key

    def case(self, prepared, items, meta: dict, gd) -> dict:
        """One case: the view buffer and the groups of ``prepared`` (a PreparedDraw)."""
        by_lighting = {id(it.lighting.ubo): it.lighting for it in items}
        groups = []
        for group in prepared.groups:
            lighting = self.upload(group.lighting, "lighting")
            packed = gd.Lighting.pack(
                by_lighting[id(group.lighting)].coefficients, by_lighting[id(group.lighting)].lamps
            )
            if _digest(packed.astype(np.float32)) != _digest(self.store.get(lighting["array"])):
                raise RuntimeError("the recorded lighting buffer differs from Lighting.pack")
            groups.append(
                {
                    "variant": variant_key(group.shader),
                    "lighting": lighting,
                    "table": self.upload(group.table, "table"),
                    "prefiltered": None
                    if group.prefiltered is None
                    else self.upload(group.prefiltered, "prefiltered"),
                    "film": None if group.film is None else self.upload(group.film, "film"),
                    "draws": [[self.mesh(batch), self.store.add(ubo.data)] for batch, ubo in group.draws],
                }
            )
        return {**meta, "view": self.store.add(prepared.view.data), "groups": groups}


def _frames(vp, scene, size):
    """The scene's cases: (meta, items, view, projection), as benchmarks/viewport.py draws them."""
    rough = vp.roughness_cases()
    for scene_name, spec in SCENES.items():
        objects, triangles = spec["layout"]
        for l_max in spec["l_max"]:
            frame = None
            try:
                for lamps in LAMPS[::-1]:  # as viewport.split_sum: lamps off first, then the default (on)
                    for case in spec["cases"]:
                        scene.material(l_max, case).thinfilm_sh.world_lamps = lamps
                        vp.prepare_scene(scene, objects, triangles, l_max, case)
                        if frame is None:
                            frame = vp.Frame(scene, *size)
                        items = frame.items()
                        meta = {
                            "id": case_id(scene_name, l_max, case, lamps),
                            "scene": scene_name,
                            "l_max": l_max,
                            "case": case,
                            "lamps": lamps,
                            "roughness": rough[case],
                            "objects": objects,
                            "triangles": scene.triangles,
                            "sh_weight": float(items[0].sh_weight),
                            "split_used": items[0].prefiltered is not None and items[0].sh_weight < 1.0,
                            "lamp_count": int(items[0].lighting.lamp_count),
                            "material_world_lamps": bool(scene.material(l_max, case).thinfilm_sh.world_lamps),
                        }
                        yield meta, items, frame.base_view, frame.proj
                        if scene_name == "sweep" and l_max in LOOP_CASES_L and case == "sh" and lamps:
                            yield (
                                dict(
                                    meta,
                                    id=case_id(scene_name, l_max, "sh-loops", lamps),
                                    case="sh-loops",
                                    loops=True,
                                ),
                                _textures_only(items) or items,
                                frame.base_view,
                                frame.proj,
                            )
                        if scene_name in TEXTURE_CASES_SCENES and l_max in TEXTURE_CASES_L:
                            tex = _textures_only(items)
                            if tex is not None:
                                yield (
                                    dict(
                                        meta,
                                        id=case_id(scene_name, l_max, case + "-tex", lamps),
                                        case=case + "-tex",
                                        textures_only=True,
                                    ),
                                    tex,
                                    frame.base_view,
                                    frame.proj,
                                )
            finally:
                if frame is not None:
                    frame.free()


def _textures_only(items):
    """The same items with the film's table read from its texture (no ``TF_TABLE_UBO``), as a
    hardware GPU draws them (``gpu_draw.TABLE_UBO_DEVICES``: only software rasterisers, where
    ``prepare`` runs, use the uniform buffer), or None where the table already is a texture. The
    lamps' film table keeps its uniform buffer, as on every device."""
    from dataclasses import replace

    if not any(it.table.ubo is not None for it in items):
        return None
    return [replace(it, table=replace(it.table, ubo=None)) for it in items]


def _check_constants(vp) -> None:
    if tuple(SCENES["sweep"]["layout"]) != tuple(vp.SWEEP_SCENE):
        raise RuntimeError(f"viewport.SWEEP_SCENE is {vp.SWEEP_SCENE}, this harness has {SCENES['sweep']}")
    if tuple(SCENES["sweep"]["l_max"]) != tuple(vp.SPLIT_SUM_L):
        raise RuntimeError(f"viewport.SPLIT_SUM_L is {vp.SPLIT_SUM_L}, this harness has {SCENES['sweep']}")


def _gl_library(names, **restypes):
    """The first of the OpenGL libraries ``names`` that loads and has the entry points of
    ``restypes`` (name → ctypes return type, which is set), or None."""
    import ctypes

    for name in names:
        try:
            lib = ctypes.CDLL(name)
            for fn, restype in restypes.items():
                getattr(lib, fn).restype = restype
            return lib
        except (OSError, AttributeError):
            continue
    return None


class _GLSources:
    """The GLSL that Blender compiled, read back from the driver (OpenGL backend only): the
    shader objects that appear while ``fn`` runs, by stage."""

    GL_SHADER_TYPE = 0x8B4F
    STAGES = {0x8B31: "vertex", 0x8B30: "fragment"}

    def __init__(self):
        import ctypes

        self.ctypes = ctypes
        self.gl = _gl_library(("libOpenGL.so.0", "libGL.so.1"), glIsShader=ctypes.c_ubyte)

    def _shaders(self, limit: int = 200_000) -> set[int]:
        found, misses, i = set(), 0, 1
        while i < limit and misses < 4096:
            if self.gl.glIsShader(i):
                found.add(i)
                misses = 0
            else:
                misses += 1
            i += 1
        return found

    def during(self, fn) -> dict[str, str] | None:
        if self.gl is None:
            return None
        before = self._shaders()
        keep = fn()  # the shader is deleted with its cache: read the sources while it lives
        new = sorted(self._shaders() - before)
        out = {}
        c = self.ctypes
        for shader in new:
            kind = c.c_int()
            self.gl.glGetShaderiv(shader, self.GL_SHADER_TYPE, c.byref(kind))
            length = c.c_int()
            self.gl.glGetShaderiv(shader, 0x8B88, c.byref(length))  # GL_SHADER_SOURCE_LENGTH
            buf = c.create_string_buffer(max(length.value, 1))
            self.gl.glGetShaderSource(shader, len(buf), c.byref(length), buf)
            stage = self.STAGES.get(kind.value)
            if stage:
                out[stage] = buf.value.decode("utf-8", "replace")
        del keep
        return out if set(out) == {"vertex", "fragment"} else None


def _blender_sources(gd, variants: dict, sources: dict, log) -> None:
    """Add each variant's GLSL as Blender compiled it (``blender_vertex`` / ``blender_fragment``)."""
    import gpu

    if gpu.platform.backend_type_get() != "OPENGL":
        log(f"  Blender's own GLSL: not read back (backend {gpu.platform.backend_type_get()})")
        return
    reader = _GLSources()
    for name, entry in variants.items():
        variant = gd.Variant(**entry["variant"])
        cache = gd.ShaderCache(generated_x90=entry.get("generated_x90", True))
        got = reader.during(lambda variant=variant, cache=cache: cache.get(*variant))
        if got is None:
            log(f"  Blender's own GLSL of {name}: not found among the driver's shader objects")
            continue
        entry["blender_vertex"] = _source_key(sources, got["vertex"])
        entry["blender_fragment"] = _source_key(sources, got["fragment"])


def record_cases(size, log=print):
    """Set up the scenes (bpy) and yield (meta, items, view, projection, capture) per case, with the
    capture active; the extension instance is created here."""
    from . import viewport as vp

    _check_constants(vp)
    ext = vp.Extension()
    capture = Capture(ext.gpu_draw)
    ext.scene_draw.CACHES.clear()
    with capture:
        scene = vp.Scene(ext)
        for meta, items, view, proj in _frames(vp, scene, size):
            yield meta, items, view, proj, capture, ext


def prepare(outdir, log=print) -> dict:
    """Record every case at :data:`RESOLUTION` into ``outdir``; returns the manifest."""
    started = time.perf_counter()
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    writer = None
    cases = []
    ext = None
    for meta, items, view, proj, capture, ext in record_cases(RESOLUTION, log):
        writer = writer or _Writer(capture)
        gd = ext.gpu_draw
        shaders = capture.loop_shaders if meta.get("loops") else capture.shaders
        prepared = gd.prepare_draw(
            items, view, proj, display_srgb=True, shaders=shaders, uniforms=capture.uniforms
        )
        cases.append(writer.case(prepared, items, meta, gd))
        log(
            f"  {meta['id']}: {len(items)} items, {prepared.draw_count} draws,"
            f" {len(prepared.groups)} group(s),"
            f" variant {cases[-1]['groups'][0]['variant']}, sh_weight {meta['sh_weight']:.2f},"
            f" lamps {meta['lamp_count']}"
        )
    capture = writer.capture
    _blender_sources(ext.gpu_draw, capture.variants, capture.sources, log)
    import gpu

    manifest = {
        "format": FORMAT_VERSION,
        "resolution": list(RESOLUTION),
        "created": time.strftime("%Y-%m-%d %H:%M:%S"),
        "code": _code_state(),
        "source_digest": source_digest(),
        "prepared_on": f"{gpu.platform.renderer_get()} ({gpu.platform.backend_type_get()})",
        "scenes": {k: {"layout": list(v["layout"]), "l_max": list(v["l_max"])} for k, v in SCENES.items()},
        "variants": capture.variants,
        "meshes": writer.meshes,
        "cases": cases,
    }
    manifest["arrays"] = writer.store.save(outdir / "arrays.npz")
    (outdir / "sources.json").write_text(json.dumps(capture.sources, indent=0), encoding="utf-8")
    (outdir / "manifest.json").write_text(json.dumps(manifest, indent=1), encoding="utf-8")
    total = sum(p.stat().st_size for p in outdir.iterdir() if p.is_file())
    log(
        f"{len(cases)} cases, {len(capture.variants)} variants, {len(writer.meshes)} meshes,"
        f" {len(writer.store.arrays)} arrays: {total / 2**20:.1f} MiB in {outdir}"
        f" ({time.perf_counter() - started:.0f} s)"
    )
    return manifest


def _code_state() -> str:
    """The revision ``prepare`` records from (``common.git_describe``; imported here, since
    ``measure`` runs where only numpy and moderngl are)."""
    from . import common

    return common.git_describe(("addon", "glsl", "precompute"))


def source_digest() -> str:
    """sha256 over the extension's drawing code (addon/*.py, glsl/*.glsl, precompute/*.py): ``check``
    compares it with the one ``prepare`` recorded."""
    h = hashlib.sha256()
    for pattern in ("addon/*.py", "glsl/*.glsl", "precompute/*.py"):
        for path in sorted(ROOT.glob(pattern)):
            h.update(path.relative_to(ROOT).as_posix().encode() + b"\0" + path.read_bytes())
    return h.hexdigest()


# ----------------------------------------------------------------------------------------------
# GLSL as Blender's OpenGL backend declares it
# ----------------------------------------------------------------------------------------------
_TYPES = {
    "FLOAT": "float",
    "VEC2": "vec2",
    "VEC3": "vec3",
    "VEC4": "vec4",
    "MAT3": "mat3",
    "MAT4": "mat4",
    "INT": "int",
    "IVEC2": "ivec2",
    "IVEC3": "ivec3",
    "IVEC4": "ivec4",
    "UINT": "uint",
    "BOOL": "bool",
}
_SAMPLERS = {
    "FLOAT_2D": "sampler2D",
    "FLOAT_2D_ARRAY": "sampler2DArray",
    "FLOAT_3D": "sampler3D",
    "FLOAT_CUBE": "samplerCube",
    "INT_2D": "isampler2D",
    "UINT_2D": "usampler2D",
}


def glsl_source(info: dict, stage: str, sources: dict) -> str:
    """The complete GLSL of one stage: declarations in the form and order Blender 5.2's OpenGL
    backend writes them (defines, typedefs, resources, inputs/interface/outputs), then the body."""
    lines = [
        "#version 430",
        "#define GPU_SHADER",
        "#define GPU_OPENGL",
        f"#define GPU_{stage.upper()}_SHADER",
    ]
    lines += [f"#define {name} {value}".rstrip() for name, value in info["defines"]]
    lines += [sources[key] for key in info["typedefs"]]
    for res in info["resources"]:
        if res["kind"] == "ubo":
            lines.append(
                f"layout(binding = {res['slot']}, std140) uniform _{res['name']}"
                f" {{ {res['type']} {res['name']}; }};"
            )
        else:
            lines.append(f"layout(binding = {res['slot']}) uniform {_SAMPLERS[res['type']]} {res['name']};")
    if stage == "vertex":
        lines += [f"layout(location = {slot}) in {_TYPES[t]} {name};" for slot, t, name in info["vertex_in"]]
    for iface in info["interfaces"]:
        qualifier = "out" if stage == "vertex" else "in"
        members = "".join(f"  {_interp(i)} {_TYPES[t]} {n};\n" for i, t, n in iface["members"])
        lines.append(f"{qualifier} {iface['name']}{{\n{members}}};")
    if stage == "fragment":
        lines.append("layout(depth_unchanged) out float gl_FragDepth;")
        lines += [
            f"layout(location = {slot}) out {_TYPES[t]} {name};" for slot, t, name in info["fragment_out"]
        ]
    lines.append(sources[info[f"{stage}_source"]])
    return "\n".join(lines)


def _interp(name: str) -> str:
    return {"smooth": "smooth", "flat": "flat", "no_perspective": "noperspective"}[name]


# ----------------------------------------------------------------------------------------------
# measure (moderngl): draw and time
# ----------------------------------------------------------------------------------------------
class _InfoLog:
    """Compile and link logs through the GL entry points (moderngl does not return the warnings of
    a successful compile); None where the library cannot be reached."""

    def __init__(self):
        import ctypes

        self.c = ctypes
        self.gl = _gl_library(
            ("libGL.so.1", "libOpenGL.so.0"), glCreateShader=ctypes.c_uint, glCreateProgram=ctypes.c_uint
        )

    def _log(self, get_iv, get_log, obj) -> str:
        c = self.c
        length = c.c_int()
        get_iv(obj, 0x8B84, c.byref(length))  # GL_INFO_LOG_LENGTH
        if length.value <= 1:
            return ""
        buf = c.create_string_buffer(length.value)
        get_log(obj, length.value, None, buf)
        return buf.value.decode("utf-8", "replace").strip()

    def compile(self, vertex: str, fragment: str) -> dict | None:
        if self.gl is None:
            return None
        gl, c = self.gl, self.c
        out, shaders = {}, []
        status = c.c_int()
        for stage, kind, text in (("vertex", 0x8B31, vertex), ("fragment", 0x8B30, fragment)):
            shader = gl.glCreateShader(kind)
            src = c.c_char_p(text.encode("utf-8"))
            gl.glShaderSource(shader, 1, c.byref(src), None)
            gl.glCompileShader(shader)
            gl.glGetShaderiv(shader, 0x8B81, c.byref(status))  # GL_COMPILE_STATUS
            out[stage] = {
                "ok": bool(status.value),
                "log": self._log(gl.glGetShaderiv, gl.glGetShaderInfoLog, shader),
            }
            shaders.append(shader)
        program = gl.glCreateProgram()
        for shader in shaders:
            gl.glAttachShader(program, shader)
        gl.glLinkProgram(program)
        gl.glGetProgramiv(program, 0x8B82, c.byref(status))  # GL_LINK_STATUS
        out["link"] = {
            "ok": bool(status.value),
            "log": self._log(gl.glGetProgramiv, gl.glGetProgramInfoLog, program),
        }
        gl.glDeleteProgram(program)
        for shader in shaders:
            gl.glDeleteShader(shader)
        return out


def create_context(backend: str | None):
    import moderngl

    kwargs = {"require": 430}
    if backend:
        kwargs["backend"] = backend
    return moderngl.create_standalone_context(**kwargs)


class Harness:
    """GPU objects of a prepared OUTDIR in one moderngl context, and frames drawn from them."""

    def __init__(self, prepared: Prepared, ctx, sources: str = "header", log=print):
        import moderngl

        self.mgl = moderngl
        self.data = prepared
        self.ctx = ctx
        self.log = log
        self.programs: dict[str, object] = {}
        self.compile_seconds: dict[str, float] = {}
        self.errors: dict[str, str] = {}
        self._buffers: dict[str, object] = {}
        self._textures: dict[str, object] = {}
        self._meshes: dict[str, tuple] = {}
        self._vaos: dict[tuple, object] = {}
        self.source_kind = sources

    # -- shaders
    def sources_of(self, name: str, kind: str | None = None) -> tuple[str, str] | None:
        kind = kind or self.source_kind
        info, src = self.data.manifest["variants"][name], self.data.sources
        if kind == "header":
            return glsl_source(info, "vertex", src), glsl_source(info, "fragment", src)
        if "blender_vertex" not in info:
            return None
        return src[info["blender_vertex"]], src[info["blender_fragment"]]

    def compile_all(self, names=None) -> None:
        """moderngl programs of every variant (compile + link timed); a failure keeps the
        driver's message (moderngl raises with the info log)."""
        for name in names or self.data.manifest["variants"]:
            pair = self.sources_of(name)
            if pair is None:
                self.errors[name] = f"no {self.source_kind} source in the prepared data"
                continue
            t0 = time.perf_counter()
            try:
                self.programs[name] = self.ctx.program(vertex_shader=pair[0], fragment_shader=pair[1])
            except Exception as exc:  # noqa: BLE001 — the driver's message is the finding
                self.errors[name] = str(exc)
                self.log(f"  {self.source_kind} {name}: FAILED\n{exc}")
                continue
            self.compile_seconds[name] = time.perf_counter() - t0
            self.log(
                f"  {self.source_kind} {name}: compiled and linked in {self.compile_seconds[name]:.2f} s"
            )

    def info_logs(self) -> dict:
        """The compile and link logs of every variant (warnings included), through the GL entry
        points: {variant: {vertex|fragment|link: {ok, log}}}; empty where they cannot be reached."""
        infolog = _InfoLog()
        out = {}
        for name in self.data.manifest["variants"]:
            pair = self.sources_of(name)
            logs = None if pair is None else infolog.compile(*pair)
            if logs is None:
                continue
            out[name] = logs
            text = " | ".join(f"{k}: {v['log']}" for k, v in logs.items() if v["log"])
            if text:
                self.log(f"  {self.source_kind} {name}: {text[:2000]}")
        return out

    # -- resources
    def buffer(self, key: str):
        if key not in self._buffers:
            self._buffers[key] = self.ctx.buffer(self.data.array(key).tobytes())
        return self._buffers[key]

    def texture(self, res: dict, role: str):
        key = res["array"]
        if key in self._textures:
            return self._textures[key]
        a = self.data.array(key)
        mgl = self.mgl
        if res["dim"] == "2d_array":
            layers, h, w = a.shape[:3]
            tex = self.ctx.texture_array((w, h, layers), 4, a.tobytes(), dtype="f4")
        elif res["dim"] == "3d":
            d, h, w = a.shape[:3]
            tex = self.ctx.texture3d((w, h, d), 4, a.tobytes(), dtype="f4")
        else:
            h, w = a.shape[:2]
            tex = self.ctx.texture((w, h), 4, a.tobytes(), dtype="f4")
        if role == "prefiltered":  # gpu_draw.PrefilterTexture: filter_mode(True), EXTEND, REPEAT in x
            tex.filter = (mgl.LINEAR, mgl.LINEAR)
            tex.repeat_x = True
            tex.repeat_y = False
            if res["dim"] == "3d":
                tex.repeat_z = False
        else:  # Blender's default sampler: no filtering, EXTEND (texelFetch ignores both)
            tex.filter = (mgl.NEAREST, mgl.NEAREST)
            tex.repeat_x = tex.repeat_y = False
        self._textures[key] = tex
        return tex

    def vao(self, variant: str, mesh_key: str):
        key = (variant, mesh_key)
        if key not in self._vaos:
            if mesh_key not in self._meshes:
                mesh = self.data.mesh(mesh_key)
                idx = mesh["indices"]
                idx = idx.astype(np.uint16) if mesh["index_bits"] == 16 else idx.astype(np.int32)
                self._meshes[mesh_key] = (
                    self.ctx.buffer(mesh["vertices"].tobytes()),
                    self.ctx.buffer(idx.tobytes()),
                    mesh["index_bits"] // 8,
                    mesh["thickness"],
                )
            vbo, ibo, size, thickness = self._meshes[mesh_key]
            fmt, attrs = ("3f 3f 1f", ("pos", "nor", "thickness")) if thickness else ("3f 3f", ("pos", "nor"))
            self._vaos[key] = self.ctx.vertex_array(
                self.programs[variant],
                [(vbo, fmt, *attrs)],
                index_buffer=ibo,
                index_element_size=size,
                skip_errors=True,
            )
        return self._vaos[key]

    def ready(self, case: dict) -> bool:
        return all(g["variant"] in self.programs for g in case["groups"])

    def warm(self, case: dict) -> None:
        """Create every GPU object of the case (uploads happen here, not in timed frames)."""
        self.buffer(case["view"])
        for g in case["groups"]:
            self._group_resources(g)
            for mesh_key, obj in g["draws"]:
                self.buffer(obj)
                self.vao(g["variant"], mesh_key)

    def _group_resources(self, g: dict) -> list:
        binds = [("ubo", 0, self.buffer(g["lighting"]["array"]))]
        for role, ubo_slot, tex_slot in (("table", 3, 0), ("film", 4, 4), ("prefiltered", None, 3)):
            res = g.get(role)
            if res is None:
                continue
            if res["kind"] == "ubo":
                binds.append(("ubo", ubo_slot, self.buffer(res["array"])))
            else:
                binds.append(("tex", tex_slot, self.texture(res, role)))
        return binds

    # -- frames
    def draw(self, case: dict, fbo) -> None:
        """Clear and draw one case into ``fbo`` (as gpu_draw.submit, see the module docstring)."""
        ctx, mgl = self.ctx, self.mgl
        fbo.use()
        fbo.depth_mask = True
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        if case is None:
            return
        ctx.enable(mgl.DEPTH_TEST)
        ctx.disable(mgl.CULL_FACE | mgl.BLEND)
        ctx.depth_func = "<="
        self.buffer(case["view"]).bind_to_uniform_block(1)
        for g in case["groups"]:
            for kind, slot, obj in self._group_resources(g):
                if kind == "ubo":
                    obj.bind_to_uniform_block(slot)
                else:
                    obj.use(location=slot)
            for mesh_key, obj in g["draws"]:
                self.buffer(obj).bind_to_uniform_block(2)
                self.vao(g["variant"], mesh_key).render(mgl.TRIANGLES)

    def framebuffer(self, size):
        color = self.ctx.renderbuffer(size, 4, dtype="f1")
        depth = self.ctx.depth_renderbuffer(size)
        return self.ctx.framebuffer(color_attachments=[color], depth_attachment=depth)

    def picture(self, case: dict, fbo) -> np.ndarray:
        """The case drawn into ``fbo``: (H, W, 4) uint8, top row first."""
        self.draw(case, fbo)
        w, h = fbo.size
        raw = fbo.read(components=4, dtype="f1")
        return np.frombuffer(raw, dtype=np.uint8).reshape(h, w, 4)[::-1].copy()

    def time_cases(self, cases: dict, fbo, warmup: int, rounds: int, budget_s=None, log=print) -> dict:
        """GPU (timer query) and wall (to glFinish) milliseconds of each case, interleaved rounds;
        with ``budget_s``, rounds stop once that many seconds have passed (after one round at least)."""
        query = self.ctx.query(time=True)
        gpu_ms = {name: [] for name in cases}
        wall_ms = {name: [] for name in cases}
        names = list(cases)
        for name in names:
            for _ in range(warmup):
                self.draw(cases[name], fbo)
            self.ctx.finish()
        start = time.perf_counter()
        for r in range(rounds):
            if r and budget_s is not None and time.perf_counter() - start > budget_s:
                log(f"  time budget of {budget_s:g} s reached after {r} rounds")
                break
            for name in names if r % 2 == 0 else names[::-1]:
                t0 = time.perf_counter()
                with query:
                    self.draw(cases[name], fbo)
                self.ctx.finish()
                t1 = time.perf_counter()
                gpu_ms[name].append(query.elapsed / 1e6)
                wall_ms[name].append((t1 - t0) * 1e3)
            if r < 2 or r % 10 == 9:
                log(f"  round {r + 1}: {time.perf_counter() - start:.1f} s")
        return {"gpu_ms": gpu_ms, "wall_ms": wall_ms}


def _context_info(ctx) -> dict:
    import moderngl

    info = dict(ctx.info)
    keep = (
        "GL_VENDOR",
        "GL_RENDERER",
        "GL_VERSION",
        "GL_SHADING_LANGUAGE_VERSION",
        "GL_MAX_UNIFORM_BLOCK_SIZE",
        "GL_MAX_ARRAY_TEXTURE_LAYERS",
        "GL_MAX_3D_TEXTURE_SIZE",
    )
    out = {k: info.get(k) for k in keep if k in info}
    gl = _InfoLog().gl
    if gl is not None:
        gl.glGetString.restype = __import__("ctypes").c_char_p
        glsl = gl.glGetString(0x8B8C)  # GL_SHADING_LANGUAGE_VERSION
        out["GL_SHADING_LANGUAGE_VERSION"] = glsl.decode() if glsl else None
    out["moderngl"] = moderngl.__version__
    out["python"] = platform.python_version()
    out["numpy"] = np.__version__
    out["machine"] = f"{platform.system()} {platform.release()} {platform.machine()}"
    return out


def _nvidia_smi() -> str | None:
    try:
        return subprocess.run(
            [
                "nvidia-smi",
                "--query-gpu=name,driver_version,memory.total,clocks.max.sm,clocks.sm,pstate",
                "--format=csv,noheader",
            ],
            capture_output=True,
            text=True,
            timeout=20,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None


def _diff(a: np.ndarray, b: np.ndarray) -> dict:
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
            name: _diff(ours[name], ref[name]) for name in ours.files if name in ref.files
        }
    Path(result_path).write_text(json.dumps(res, indent=1), encoding="utf-8")
    return res["vs_check_pictures"]


def _summary(values: list[float]) -> dict:
    s = sorted(values)
    n = len(s)
    return {
        "median": statistics.median(s),
        "p10": s[int(0.1 * (n - 1))],
        "p90": s[int(0.9 * (n - 1))],
        "min": s[0],
        "n": n,
    }


def _parse_size(text: str) -> tuple[int, int]:
    w, h = text.lower().split("x")
    return int(w), int(h)


def measure(
    outdir,
    out,
    *,
    backend: str | None = "egl",
    size=RESOLUTION,
    warmup: int = WARMUP,
    rounds: int = ROUNDS,
    pictures: str | None = None,
    picture_size=CHECK_SIZE,
    png_cases=PNG_CASES,
    scenes=None,
    blender_sources: bool = True,
    skip=(),
    budget_s: float | None = None,
    log=print,
) -> dict:
    """Compile, draw and time every case of ``outdir``; write the result JSON to ``out``."""
    started = time.perf_counter()
    data = Prepared(outdir)
    if skip:
        import fnmatch

        data.manifest["cases"] = [
            c for c in data.manifest["cases"] if not any(fnmatch.fnmatch(c["id"], pat) for pat in skip)
        ]
        used = {g["variant"] for c in data.manifest["cases"] for g in c["groups"]}
        data.manifest["variants"] = {k: v for k, v in data.manifest["variants"].items() if k in used}
    ctx = create_context(backend)
    res: dict = {
        "format": FORMAT_VERSION,
        "context": _context_info(ctx),
        "nvidia_smi": _nvidia_smi(),
        "prepared": {k: data.manifest[k] for k in ("created", "code", "prepared_on", "resolution")},
        "size": list(size),
        "warmup": warmup,
        "rounds": rounds,
        "skipped": list(skip),
        "budget_s": budget_s,
        "cases": {},
        "command": " ".join(["python -m benchmarks.gpu_frame", *sys.argv[1:]]),
    }
    log(" | ".join(str(res["context"].get(k)) for k in ("GL_RENDERER", "GL_VERSION", "GL_VENDOR")))
    harness = Harness(data, ctx, "header", log)
    harness.compile_all()
    res["compile"] = {
        name: {"seconds": harness.compile_seconds.get(name), "error": harness.errors.get(name)}
        for name in data.manifest["variants"]
    }
    fbo = harness.framebuffer(tuple(size))
    for case in data.cases():
        res["cases"][case["id"]] = {
            k: case[k]
            for k in (
                "scene",
                "l_max",
                "case",
                "lamps",
                "roughness",
                "sh_weight",
                "lamp_count",
                "triangles",
                "objects",
            )
        }
        res["cases"][case["id"]]["variant"] = case["groups"][0]["variant"]
        res["cases"][case["id"]]["drawn"] = harness.ready(case)
    # timing, one scene at a time
    for scene in scenes or data.manifest["scenes"]:
        cases = {c["id"]: c for c in data.cases(scene) if harness.ready(c)}
        if not cases or rounds <= 0:
            continue
        for case in cases.values():
            harness.warm(case)
        cases[f"{scene}-clear"] = None
        log(f"timing {scene}: {len(cases)} cases × {rounds} rounds after {warmup} warm-up frames …")
        t0 = time.perf_counter()
        timed = harness.time_cases(cases, fbo, warmup, rounds, budget_s, log)
        res.setdefault("rounds_done", {})[scene] = len(timed["gpu_ms"][f"{scene}-clear"])
        for name in cases:
            entry = res["cases"].setdefault(name, {"scene": scene, "case": "clear"})
            entry["gpu_ms"] = _summary(timed["gpu_ms"][name])
            entry["wall_ms"] = _summary(timed["wall_ms"][name])
            entry["gpu_samples"] = [round(x, 4) for x in timed["gpu_ms"][name]]
            entry["wall_samples"] = [round(x, 4) for x in timed["wall_ms"][name]]
            log(f"  {name}: GPU {entry['gpu_ms']['median']:.3f} ms, wall {entry['wall_ms']['median']:.3f} ms")
        log(f"  ({time.perf_counter() - t0:.1f} s)")
        _write(out, res, started)
    # pictures: coverage at full size, PNGs of a few, all at picture_size (and compared)
    pics, blender_pics = {}, {}
    small = harness.framebuffer(tuple(picture_size))
    for case in data.cases():
        if not harness.ready(case):
            continue
        full = harness.picture(case, fbo)
        res["cases"][case["id"]]["coverage"] = float(np.mean(full[..., 3] > 0))
        if pictures and case["id"] in png_cases:
            _save_picture(Path(pictures) / f"{case['id']}.png", full)
        pics[case["id"]] = harness.picture(case, small)
    if pictures:
        Path(pictures).mkdir(parents=True, exist_ok=True)
        np.savez_compressed(Path(pictures) / f"pictures-{picture_size[0]}x{picture_size[1]}.npz", **pics)
    res["picture_size"] = list(picture_size)
    _write(out, res, started)  # the measurements, before anything else can fail
    if blender_sources and any("blender_vertex" in v for v in data.manifest["variants"].values()):
        log("Blender's own GLSL (as compiled by bpy on the machine that prepared OUTDIR):")
        theirs = Harness(data, ctx, "blender", log)
        theirs.compile_all()
        res["blender_source"] = {
            "compile": {
                name: {"seconds": theirs.compile_seconds.get(name), "error": theirs.errors.get(name)}
                for name in data.manifest["variants"]
            },
            "vs_header": {},
        }
        for case in data.cases():
            if theirs.ready(case) and case["id"] in pics:
                blender_pics[case["id"]] = theirs.picture(case, small)
                res["blender_source"]["vs_header"][case["id"]] = _diff(
                    blender_pics[case["id"]], pics[case["id"]]
                )
    reference = Path(outdir) / "pictures-check.npz"
    if reference.exists() and tuple(picture_size) == CHECK_SIZE:
        with np.load(reference) as ref:
            res["vs_check_pictures"] = {
                name: _diff(pics[name], ref[name]) for name in pics if name in ref.files
            }
        check = Path(outdir) / "check.json"
        if check.exists():
            res["check"] = json.loads(check.read_text(encoding="utf-8"))
    res["picture_size"] = list(picture_size)
    _write(out, res, started)
    # Last, so that whatever happens in it the measurements are written: the compile logs of a
    # second compile through the GL entry points (moderngl keeps a successful compile's warnings).
    log("compile and link logs:")
    for name, logs in harness.info_logs().items():
        res["compile"][name].update(logs)
    if "blender_source" in res:
        for name, logs in theirs.info_logs().items():
            res["blender_source"]["compile"][name].update(logs)
    res["info_logs"] = any("fragment" in v for v in res["compile"].values())
    _write(out, res, started)
    return res


def _write(out, res: dict, started: float) -> None:
    res["seconds"] = time.perf_counter() - started
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Path(out).write_text(json.dumps(res, indent=1), encoding="utf-8")
    print(f"wrote {out} ({res['seconds']:.0f} s)")


def _save_picture(path: Path, rgba: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        from PIL import Image
    except ImportError:
        path = path.with_suffix(".npy")
        np.save(path, rgba)
        return path
    Image.fromarray(rgba, "RGBA").save(path)
    return path


# ----------------------------------------------------------------------------------------------
# check (bpy + moderngl in a subprocess): the harness's pictures against the product's
# ----------------------------------------------------------------------------------------------
def check(outdir, log=print) -> dict:
    """Draw every case with ``gpu_draw.draw_items`` at :data:`CHECK_SIZE` and with ``measure`` on
    the same OpenGL; compare the 8-bit pictures. Writes OUTDIR/check.json and the harness's
    pictures to OUTDIR/pictures-check.npz."""
    import tempfile

    import bpy  # noqa: F401 (gpu is importable once bpy is)
    import gpu

    outdir = Path(outdir)
    data = Prepared(outdir)
    stored = {c["id"]: c for c in data.cases()}
    w, h = CHECK_SIZE
    ours, notes = {}, []
    if data.manifest.get("source_digest") != source_digest():
        notes.append(
            "addon/, glsl/ or precompute/ differ from what prepare recorded: gpu_draw now draws other"
            " shaders or data than the prepared ones (run prepare again)"
        )
    for meta, items, view, proj, _capture, ext in record_cases(CHECK_SIZE, log):
        gd = ext.gpu_draw
        view_ubo = gd.view_uniforms(view, proj)
        recorded = data.array(stored[meta["id"]]["view"])
        if not np.array_equal(view_ubo.astype(np.float32), recorded):
            notes.append(f"{meta['id']}: the view at {w}×{h} differs from the prepared one")
        offscreen = gpu.types.GPUOffScreen(w, h, format="RGBA8")
        try:
            with offscreen.bind():
                fb = gpu.state.active_framebuffer_get()
                fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
                gd.draw_items(items, view, proj, display_srgb=True)
                buf = fb.read_color(0, 0, w, h, 4, 0, "UBYTE")
                buf.dimensions = w * h * 4
                ours[meta["id"]] = np.asarray(buf, dtype=np.uint8).reshape(h, w, 4)[::-1].copy()
        finally:
            offscreen.free()
        log(f"  Blender drew {meta['id']}")
    renderer = f"{gpu.platform.renderer_get()} ({gpu.platform.backend_type_get()})"
    with tempfile.TemporaryDirectory(prefix="tf_gpu_frame_check_") as tmp:
        cmd = [
            sys.executable,
            "-m",
            "benchmarks.gpu_frame",
            "measure",
            str(outdir),
            "--out",
            os.path.join(tmp, "result.json"),
            "--size",
            f"{w}x{h}",
            "--rounds",
            "0",
            "--pictures",
            tmp,
            "--picture-size",
            f"{w}x{h}",
            "--png",
        ]
        log("harness: " + " ".join(cmd[1:]))
        subprocess.run(cmd, cwd=ROOT, check=True)
        harness_result = json.loads(Path(tmp, "result.json").read_text(encoding="utf-8"))
        with np.load(Path(tmp) / f"pictures-{w}x{h}.npz") as npz:
            theirs = {k: npz[k] for k in npz.files}
    np.savez_compressed(outdir / "pictures-check.npz", **theirs)
    cases = {name: _diff(theirs[name], ours[name]) for name in ours if name in theirs}
    for name in ours:
        if name not in theirs:
            notes.append(f"{name}: not drawn by the harness")
    result = {
        "size": [w, h],
        "blender_renderer": renderer,
        "harness_renderer": harness_result["context"].get("GL_RENDERER"),
        "cases": cases,
        "max": max(c["max"] for c in cases.values()),
        "mean": statistics.mean(c["mean"] for c in cases.values()),
        "coverage": {name: float(np.mean(ours[name][..., 3] > 0)) for name in ours},
        "notes": notes,
    }
    if "blender_source" in harness_result:
        result["blender_source_vs_header"] = harness_result["blender_source"]["vs_header"]
    (outdir / "check.json").write_text(json.dumps(result, indent=1), encoding="utf-8")
    log(
        f"harness vs gpu_draw.draw_items on {renderer}, {w}×{h} RGBA8: max {result['max']} levels,"
        f" mean {result['mean']:.4f} over {len(cases)} cases" + ("; " + "; ".join(notes) if notes else "")
    )
    return result


# ----------------------------------------------------------------------------------------------
# report
# ----------------------------------------------------------------------------------------------
def _ms(entry: dict | None, key: str = "gpu_ms") -> float | None:
    return None if not entry or key not in entry else entry[key]["median"]


def _f(x: float | None, fmt: str = "{:.3f}") -> str:
    return "—" if x is None else fmt.format(x)


def _ratio(a: float | None, b: float | None) -> str:
    return "—" if a is None or b is None or b <= 0 else f"{a / b:.2f}×"


def report(res: dict) -> str:
    ctx = res["context"]
    renderer = ctx.get("GL_RENDERER", "?")
    lines = [
        "# GPU frame time of our draw (moderngl harness)",
        "",
        "Generated by `python -m benchmarks.gpu_frame report`"
        f" from `{res.get('result_path', 'RESULT.json')}`,"
        " which `python3 -m benchmarks.gpu_frame measure` wrote on the GPU machine (the module docstring of"
        " benchmarks/gpu_frame.py describes every step). The measured JSON is docs/gpu-frame.json.",
        "",
        "## Device",
        "",
        f"- Renderer: **{renderer}**; vendor {ctx.get('GL_VENDOR')}; OpenGL {ctx.get('GL_VERSION')};"
        f" GLSL {ctx.get('GL_SHADING_LANGUAGE_VERSION')}",
    ]
    if any(name in renderer for name in ("H100", "H200", "A100")):
        lines.append(
            "- **Caveat: a data-centre GPU with little graphics hardware.** Hopper (GH100) has raster and"
            " pixel-shading hardware in only a small part of the chip (press reports of NVIDIA's whitepaper:"
            " one GPC; 8 ROPs on the H100, which scores below an integrated Radeon 680M in 3DMark Time Spy),"
            " and a test on these machines ran the same arithmetic 30 times slower in a fragment shader than"
            " in a compute shader (/work/.library/device/KINDS.md). Our cost is fragment shading, so these"
            " frame times are a pessimistic bound for a desktop GPU of the same generation, not an estimate"
            " of one; ratios between cases carry over better than absolute times."
        )
    if res.get("nvidia_smi"):
        lines.append(
            "- nvidia-smi (name, driver, memory, max SM clock, SM clock and P-state at the start):"
            f" {res['nvidia_smi']}"
        )
    lines += [
        f"- Harness: moderngl {ctx.get('moderngl')}, Python {ctx.get('python')}, numpy {ctx.get('numpy')};"
        f" {ctx.get('machine')}",
        f"- Data prepared {res['prepared']['created']} from {res['prepared']['code']}, with bpy on"
        f" {res['prepared']['prepared_on']}",
        "",
        "## Method",
        "",
        "- **What is timed: our draw only**: one frame = clear (colour 0, depth 1) of a"
        f" {res['size'][0]}×{res['size'][1]} RGBA8 framebuffer with depth, then every draw of the"
        " scene with the extension's shaders and data, as `gpu_draw.submit` issues it (depth test"
        " LEQUAL, no blending, no culling, display sRGB output). **GPU time** = a `GL_TIME_ELAPSED`"
        " query around the frame; **wall** = from the first call to the return of `glFinish`"
        " (CPU submission + GPU + synchronisation).",
        "- **Not included**: Blender's draw manager and the Workbench pass the viewport draws underneath,"
        " and the Python work per frame (`scene_draw.collect`, `prepare_draw`); docs/performance.md"
        " measures those (on llvmpipe). bpy cannot run on the GPU machine, so the extension's shaders and"
        " data were recorded with bpy (`prepare`) and are drawn here by moderngl over EGL.",
        "- **Same shaders, same data**: the GLSL bodies and create-info of every variant are those"
        " `gpu_draw` builds; the declarations are written as Blender 5.2's OpenGL backend writes them."
        " Uniform buffers, textures (RGBA32F), meshes (one vertex per face corner, as `MeshBatch`) and"
        " the grouping of the draws are recorded from the extension itself. The picture check below shows"
        " that the harness draws what `gpu_draw.draw_items` draws.",
        f"- **Rounds**: {res['warmup']} warm-up frames per case, then {res['rounds']} rounds over the"
        " cases of one scene, every case once per round, the order reversed every other round; medians"
        " (10th–90th percentile in the JSON). `clear` = the clear alone.",
        "- **Scenes** (benchmarks/viewport.py's): Blender's `studio` HDRI as the World, the 400 nm film of"
        " n = 1.33 on glass (spectral, constant thickness); *SH only*, *combined* (split sum + SH) and"
        " *split only* are the same film at the roughness of `viewport.roughness_cases()`; *lamps* = the"
        " World's lamps shaded per light direction (the product's default), *no lamps* = the films'"
        ' "World Lamps" off.',
        "",
    ]
    lines += _sweep_tables(res)
    lines += _grid_section(res)
    lines += _picture_section(res)
    lines += _compile_section(res)
    lines += _extra_section(res)
    lines += _supplement_section(res)
    return "\n".join(lines).rstrip() + "\n"


def _gpu_case(cases: dict, scene: str, l_max: int, name: str, tag: str) -> dict | None:
    """The case as a hardware GPU draws it: the "-tex" twin (table from the texture) where there
    is one, else the case itself (its table was a texture already)."""
    return cases.get(f"{scene}-l{l_max}-{name}-tex-{tag}") or cases.get(f"{scene}-l{l_max}-{name}-{tag}")


def _sweep_tables(res: dict) -> list[str]:
    cases = res["cases"]
    sweep = [c for c in cases.values() if c.get("scene") == "sweep" and "l_max" in c]
    if not sweep:
        return []
    first = sweep[0]
    orders = sorted({c["l_max"] for c in sweep})
    skipped = sorted(
        {int(m.group(1)) for pat in res.get("skipped", []) if (m := re.fullmatch(r"sweep-l(\d+)-\*", pat))}
        - set(orders)
    )
    out = [
        "## SH only, combined, split only (10 tori, 100 k triangles)",
        "",
        f"{first['objects']} objects, {first['triangles']:,} triangles, {res['size'][0]}×{res['size'][1]}."
        f" GPU time, median ms (clear alone: {_f(_ms(cases.get('sweep-clear')))} ms).",
        "",
        "### As a GPU draws it",
        "",
        "Films' tables read from their textures (`gpu_draw.TABLE_UBO_DEVICES`: only software rasterisers"
        " read small tables from the uniform buffer), the lamps' film table from its uniform buffer.",
        "",
        "| l | World lamps | SH only | combined | split only | combined ÷ SH only | split only ÷ SH only |",
        "|---|---|---|---|---|---|---|",
    ]
    for l_max in orders:
        for lamps in (True, False):
            tag = "lamps" if lamps else "nolamps"
            sh, comb, split = (
                _ms(_gpu_case(cases, "sweep", l_max, n, tag)) for n in ("sh", "combined", "split")
            )
            out.append(
                f"| {l_max} | {'on' if lamps else 'off'} | {_f(sh)} | {_f(comb)} | {_f(split)} |"
                f" **{_ratio(comb, sh)}** | {_ratio(split, sh)} |"
            )
    for l_max in skipped:
        out.append(f"| {l_max} | — | not measured at this size (see *Further runs*) | | | | |")
    merged = sorted({c["l_max"] for c in sweep if c.get("merged_from")})
    if merged:
        out += [
            "",
            f"l = {', '.join(str(m) for m in merged)}: from a separate run of the same data on the same"
            " machine (*Further runs*; fewer rounds).",
        ]
    out += [
        "",
        "### As llvmpipe draws it, and the table's two layouts",
        "",
        "The cases as `prepare` recorded them on llvmpipe (ᵁ: the table from the uniform buffer,"
        " `TF_TABLE_UBO`), and where a film's table fits the uniform buffer the same film with it read"
        " from the texture: same variant otherwise, same pictures.",
        "",
        "| l | World lamps | SH only | combined | split only | combined ÷ SH only"
        " | same films, table from the texture: SH only | combined | split only |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for l_max in orders:
        for lamps in (True, False):
            tag = "lamps" if lamps else "nolamps"
            got = [cases.get(f"sweep-l{l_max}-{n}-{tag}") for n in ("sh", "combined", "split")]
            tex = [cases.get(f"sweep-l{l_max}-{n}-tex-{tag}") for n in ("sh", "combined", "split")]
            ms = [_ms(c) for c in got]
            marks = [_f(m) + _ubo_mark(c) if m is not None else "—" for m, c in zip(ms, got, strict=True)]
            out.append(
                f"| {l_max} | {'on' if lamps else 'off'} | {' | '.join(marks)} | {_ratio(ms[1], ms[0])} |"
                f" {' | '.join(_f(_ms(c)) if c else '—' for c in tex)} |"
            )
    walls = [abs(_ms(c, "wall_ms") - _ms(c)) for c in sweep if _ms(c) is not None and _ms(c, "wall_ms")]
    weights = {c["case"]: c for c in sweep}
    out += [
        "",
        "On this driver a uniform-buffer table read with an index that depends on the pixel (the view"
        " angle) is far slower than the texture: the threads of a warp read different addresses, and"
        " NVIDIA's uniform path serialises them. On llvmpipe it is the cheaper of the two"
        " (docs/performance.md), hence `gpu_draw.TABLE_UBO_DEVICES`. The lamps' film table (a few texels"
        " per lamp) measured faster from its uniform buffer on both.",
        "",
        "Roughness and SH weight of the three films: "
        + "; ".join(
            f"{name} {weights[name]['roughness']:g} (sh_weight {weights[name]['sh_weight']:.2f})"
            for name in ("sh", "combined", "split")
            if name in weights
        )
        + f". World lamps shaded: {max(c['lamp_count'] for c in sweep)}."
        + _coverage(sweep)
        + (
            f" Wall time to `glFinish` is within {max(walls):.2f} ms of the GPU time in every case."
            if walls
            else ""
        ),
        "",
    ]
    return out


def _ubo_mark(case: dict | None) -> str:
    return "ᵁ" if case and "table_ubo" in case.get("variant", "") else ""


def _coverage(cases: list[dict]) -> str:
    cov = [c["coverage"] for c in cases if "coverage" in c]
    if not cov:
        return ""
    span = f"{100 * min(cov):.1f}" + (f"–{100 * max(cov):.1f}" if max(cov) > min(cov) else "")
    return f" The films cover {span} % of the frame's pixels."


def _grid_section(res: dict) -> list[str]:
    cases = res["cases"]
    grid = sorted(
        (c for c in cases.values() if c.get("scene") == "grid" and "l_max" in c),
        key=lambda c: (-c["l_max"], not c["lamps"]),
    )
    if not grid:
        return []
    out = [
        "## 1 M triangles: the GPU acceptance figure",
        "",
        f"1 torus, {grid[0]['triangles']:,} triangles, {res['size'][0]}×{res['size'][1]}, SH only. The"
        f" product's earlier acceptance asked for ≥ {FPS_TARGET:.0f} fps at 1080p with 1 M triangles at SH"
        " order 5 (l_max = 4) on a GPU. fps = 1000 / median frame ms (our draw only, see Method).",
        "",
        "| SH order (l_max) | World lamps | GPU ms | GPU fps | wall ms | wall fps | ≥ 240 fps (GPU time) |",
        "|---|---|---|---|---|---|---|",
    ]
    # as a GPU draws it (the table from its texture) first, then the uniform-buffer table
    grid.sort(key=lambda c: (not c["case"].endswith("-tex"), -c["l_max"], not c["lamps"]))
    out[-2] = (
        "| SH order (l_max) | World lamps | table | GPU ms | GPU fps | wall ms | wall fps"
        " | ≥ 240 fps (GPU time) |"
    )
    out[-1] = "|---|---|---|---|---|---|---|---|"
    for c in grid:
        gpu_ms, wall = _ms(c), _ms(c, "wall_ms")
        layout = "texture (as on a GPU)" if c["case"].endswith("-tex") else "uniform buffer" + _ubo_mark(c)
        ok = "—" if gpu_ms is None else ("yes" if 1e3 / gpu_ms >= FPS_TARGET else "**no**")
        out.append(
            f"| {c['l_max'] + 1} ({c['l_max']}) | {'on' if c['lamps'] else 'off'} | {layout} | {_f(gpu_ms)} |"
            f" {_f(None if gpu_ms is None else 1e3 / gpu_ms, '{:.0f}')} | {_f(wall)} |"
            f" {_f(None if wall is None else 1e3 / wall, '{:.0f}')} | {ok} |"
        )
    out += ["", f"Clear alone: {_f(_ms(cases.get('grid-clear')))} ms GPU."]
    if any(name in res["context"].get("GL_RENDERER", "") for name in ("H100", "H200", "A100")):
        out.append(
            "This is a data-centre GPU with little graphics hardware (caveat under *Device*): the verdict"
            " column holds for this GPU only and says nothing about a desktop GPU."
        )
    out.append("")
    return out


def _picture_section(res: dict) -> list[str]:
    out = ["## Picture check", ""]
    check = res.get("check")
    if check:
        out.append(
            f"- **Harness vs the product** (`check`, {check['size'][0]}×{check['size'][1]}, RGBA8, display"
            f" sRGB, both on {check['blender_renderer']}): `gpu_draw.draw_items` in bpy against this"
            f" harness over {len(check['cases'])} cases: max {check['max']} levels (of 255), mean"
            f" {check['mean']:.4f}; largest per case "
            + ", ".join(
                f"{k} {v['max']}" for k, v in sorted(check["cases"].items(), key=lambda kv: -kv[1]["max"])[:3]
            )
            + "."
        )
        if check.get("notes"):
            out.append("  Notes: " + "; ".join(check["notes"]))
    bs = res.get("blender_source", {}).get("vs_header") or (check or {}).get("blender_source_vs_header")
    if bs:
        where = (
            "on this driver" if res.get("blender_source", {}).get("vs_header") else "in `check`, on llvmpipe"
        )
        out.append(
            "- **Blender's own GLSL vs the harness's declarations** (the source bpy compiled, read back"
            f" from the driver by `prepare`, compiled and drawn by the harness {where}):"
            f" max {max(x['max'] for x in bs.values())} levels over {len(bs)} cases. Blender 5.2 strips"
            " the comments of our GLSL and marks `out` parameters with empty macros; otherwise its bodies"
            " are ours token for token."
        )
    vs = res.get("vs_check_pictures")
    if vs:
        out += _driver_comparison(res, vs)
    if len(out) == 2:
        out.append("No picture comparison in this result.")
    return out + [""]


def _driver_comparison(res: dict, vs: dict) -> list[str]:
    name = res["context"].get("GL_RENDERER")
    size = res["picture_size"]
    covered = [d.get("covered_px", 0) for d in vs.values()]
    mean_all = statistics.mean(d["mean"] for d in vs.values())
    out = [
        f"- **{name} vs llvmpipe** (this harness on both, {size[0]}×{size[1]} RGBA8, the pictures of"
        f" `check` as reference), {len(vs)} cases: all pixels and channels, max"
        f" {max(d['max'] for d in vs.values())} levels, mean {mean_all:.4f}."
    ]
    if all("inside_max" in d for d in vs.values()):
        mismatch = max(d["coverage_mismatch_px"] for d in vs.values())
        out[-1] += (
            " The same pixels are covered in every case."
            if mismatch == 0
            else f" Coverage differs in {mismatch} pixels at most."
        )
        out[-1] += (
            f" Over the {min(covered):,}–{max(covered):,}"
            f" covered pixels: mean {statistics.mean(d['inside_mean'] for d in vs.values()):.4f} levels;"
            f" pixels off by more than 1 level: {min(d['over_1_px'] for d in vs.values())}–"
            f"{max(d['over_1_px'] for d in vs.values())} per case; by more than 8 levels:"
            f" {max(d['over_8_px'] for d in vs.values())} per case at most (silhouette pixels, where the"
            " interpolated normal is nearly perpendicular to the view and the shading is ill-conditioned)."
        )
        out += [
            "",
            "| case | max (all) | covered px | mean (covered) | px > 1 level | px > 8 levels |",
            "|---|---|---|---|---|---|",
        ]
        out += [
            f"| {k} | {d['max']} | {d['covered_px']:,} | {d['inside_mean']:.4f} | {d['over_1_px']} |"
            f" {d['over_8_px']} |"
            for k, d in vs.items()
        ]
    return out


def _extra_section(res: dict) -> list[str]:
    """Cases of further ``measure`` runs merged in by ``report --extra`` (other sizes or cases,
    possibly data prepared from other code: the *code* column)."""
    extra = res.get("extra")
    if not extra:
        return []
    main_code = res["prepared"]["code"]
    out = [
        "## Further runs",
        "",
        "Separate `measure` runs on this kind of machine, merged into the JSON by `report --extra`: l = 12"
        " (whose frames took seconds before the band-by-band sum) and the rotation's two forms. *loops*:"
        " the same variant with the generic rotation loops of glsl/tf_sh_rotate.glsl"
        " (`ShaderCache(generated_x90=False)`) instead of the generated code. *code*: the revision the"
        " run's data and shaders were prepared from (\"this report's\" = the tables above).",
        "",
        "| run | code | case | size | rounds | GPU ms | compile + link s |",
        "|---|---|---|---|---|---|---|",
    ]
    for k, run in enumerate(extra, 1):
        size = "×".join(str(x) for x in run["size"])
        code = run.get("prepared", {}).get("code", "?")
        code = "this report's" if code == main_code else code.split(" 20")[0]
        rounds = run.get("rounds_done", run.get("rounds"))
        if isinstance(rounds, dict):
            rounds = ", ".join(str(v) for v in rounds.values())
        for cid, c in run["cases"].items():
            if "l_max" not in c:
                continue
            comp = (run.get("compile") or {}).get(c.get("variant", ""), {})
            secs = comp.get("seconds") if isinstance(comp, dict) else None
            out.append(f"| {k} | {code} | {cid} | {size} | {rounds} | {_f(_ms(c))} | {_f(secs, '{:.1f}')} |")
    out += [""] + _extra_findings(extra, main_code)
    return out + [""]


def _extra_findings(extra: list[dict], main_code: str) -> list[str]:
    """l = 12 before and after, l = 12 against l = 8 and loops ÷ generated, each at one frame size."""
    ms: dict[tuple, float] = {}  # (current code?, size, l, case) → GPU ms (first run that has it)
    for run in extra:
        current = run.get("prepared", {}).get("code") == main_code
        size = "×".join(str(x) for x in run["size"])
        for c in run["cases"].values():
            if "l_max" in c and _ms(c) is not None and c["lamps"] and c["case"] in ("sh", "sh-loops"):
                ms.setdefault((current, size, c["l_max"], c["case"]), _ms(c))
    lines = []
    for size in sorted({k[1] for k in ms}):
        old, new = ms.get((False, size, 12, "sh")), ms.get((True, size, 12, "sh"))
        if old and new:
            lines.append(
                f"- SH only with lamps at l = 12, {size}: {old:.0f} → {new:.1f} ms ({old / new:.0f}× faster)"
                " with the band-by-band sum (`gpu_draw.banded_source`: each band rotated and summed in its"
                " own variables, one band live at a time) instead of every band rotated in the (l + 1)²"
                " array `tf_c` before the sum (507 floats at l = 12, against at most 255 registers per"
                " thread)."
            )
        for current, label in ((True, "now"), (False, "before")):
            l8, l12 = ms.get((current, size, 8, "sh")), ms.get((current, size, 12, "sh"))
            if l8 and l12:
                lines.append(
                    f"- {size} ({label}): l = 12 costs {l12 / l8:.1f}× l = 8 (91 against 45 coefficients;"
                    " on llvmpipe the step is about 2.3×, docs/performance.md)."
                )
            for l_max in (8, 12):
                gen, loops = ms.get((current, size, l_max, "sh")), ms.get((current, size, l_max, "sh-loops"))
                if gen and loops:
                    lines.append(
                        f"- {size} ({label}), l = {l_max}: the loops cost {loops / gen:.2f}× the generated"
                        " code."
                    )
    return lines


def _supplement_section(res: dict) -> list[str]:
    sup = res.get("supplement")
    if not sup:
        return []
    out = [
        "## Further runs",
        "",
        "From the logs of the device runs (the JSON's `supplement`, added to the measured result by hand):",
        "",
    ]
    out += [f"- {line}" for line in sup.get("notes", [])]
    return out + [""]


def _compile_section(res: dict) -> list[str]:
    out = ["## Shader compilation on this driver", ""]
    comp = res.get("compile", {})
    errors = {k: v for k, v in comp.items() if v.get("error")}
    logs = {
        k: {
            s: v[s]["log"]
            for s in ("vertex", "fragment", "link")
            if isinstance(v.get(s), dict) and v[s]["log"]
        }
        for k, v in comp.items()
    }
    logs = {k: v for k, v in logs.items() if v}
    out.append(
        f"{len(comp)} variants; {len(errors)} failed; {len(logs)} with a compiler or linker message."
        " Compile + link time per variant (moderngl program): "
        + ", ".join(f"{k} {v['seconds']:.2f} s" for k, v in comp.items() if v.get("seconds") is not None)
        + "."
    )
    for name, v in errors.items():
        out += ["", f"**{name}: error**", "", "```", v["error"].strip(), "```"]
    for name, stages in logs.items():
        for stage, text in stages.items():
            out += ["", f"{name}, {stage}:", "", "```", text.strip(), "```"]
    bs = res.get("blender_source", {}).get("compile", {})
    bad = {k: v for k, v in bs.items() if v.get("error")}
    if bs:
        out += ["", f"Blender's own GLSL for the same variants: {len(bad)} of {len(bs)} failed."]
        for name, v in bad.items():
            out += ["", f"**{name} (Blender's GLSL): error**", "", "```", v["error"].strip(), "```"]
    return out + [""]


# ----------------------------------------------------------------------------------------------
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("prepare", help="record shaders and data with bpy")
    p.add_argument("outdir")
    p = sub.add_parser("check", help="harness pictures vs gpu_draw.draw_items (bpy + moderngl)")
    p.add_argument("outdir")
    p = sub.add_parser("measure", help="compile, draw and time (numpy + moderngl)")
    p.add_argument("outdir")
    p.add_argument("--out", required=True, help="result JSON")
    p.add_argument("--backend", default="egl", help="moderngl standalone backend (default egl; '' = default)")
    p.add_argument("--size", default=f"{RESOLUTION[0]}x{RESOLUTION[1]}", help="frame size WxH")
    p.add_argument("--warmup", type=int, default=WARMUP)
    p.add_argument("--rounds", type=int, default=ROUNDS, help="timed rounds per scene (0: no timing)")
    p.add_argument("--scenes", nargs="+", help="time only these scenes")
    p.add_argument("--pictures", help="folder for pictures-WxH.npz and a few PNGs")
    p.add_argument("--picture-size", default=f"{CHECK_SIZE[0]}x{CHECK_SIZE[1]}")
    p.add_argument("--png", nargs="*", default=list(PNG_CASES), help="cases saved as full-size PNG")
    p.add_argument("--no-blender-sources", action="store_true", help="skip Blender's own GLSL")
    p.add_argument(
        "--skip", nargs="+", default=[], metavar="PATTERN", help="leave out cases (fnmatch on ids)"
    )
    p.add_argument("--budget-s", type=float, help="stop a scene's rounds after this many seconds")
    p = sub.add_parser("compare", help="recompute a result's picture comparison (numpy only)")
    p.add_argument("result")
    p.add_argument("pictures", help="the pictures-WxH.npz that measure --pictures wrote with the result")
    p.add_argument("reference", help="OUTDIR/pictures-check.npz")
    p = sub.add_parser("report", help="write docs/gpu-frame.md from a result JSON")
    p.add_argument("result")
    p.add_argument(
        "--extra", nargs="+", help="results of further measure runs: merged into docs/gpu-frame.json first"
    )
    args = parser.parse_args(argv)
    if args.command == "prepare":
        prepare(args.outdir)
    elif args.command == "check":
        result = check(args.outdir)
        return 0 if result["max"] <= 1 and not result["notes"] else 1
    elif args.command == "measure":
        measure(
            args.outdir,
            args.out,
            backend=args.backend or None,
            size=_parse_size(args.size),
            warmup=args.warmup,
            rounds=args.rounds,
            pictures=args.pictures,
            picture_size=_parse_size(args.picture_size),
            png_cases=tuple(args.png),
            scenes=args.scenes,
            blender_sources=not args.no_blender_sources,
            skip=tuple(args.skip),
            budget_s=args.budget_s,
        )
    elif args.command == "compare":
        for name, d in compare(args.result, args.pictures, args.reference).items():
            print(f"{name}: max {d['max']}, covered mean {d['inside_mean']:.4f}, >1: {d['over_1_px']} px")
    else:
        res = json.loads(Path(args.result).read_text(encoding="utf-8"))
        if args.extra:
            res["extra"] = [
                {
                    k: run.get(k)
                    for k in ("command", "size", "rounds", "rounds_done", "cases", "compile", "prepared")
                }
                for run in (json.loads(Path(e).read_text(encoding="utf-8")) for e in args.extra)
            ]
            for run in res["extra"]:  # same data, same frame size: the main tables take its cases
                if (
                    run.get("prepared", {}).get("code") == res["prepared"]["code"]
                    and run["size"] == res["size"]
                ):
                    for cid, case in run["cases"].items():
                        if cid not in res["cases"]:
                            res["cases"][cid] = dict(case, merged_from=run.get("command"))
            merged = ROOT / "docs" / "gpu-frame.json"
            merged.write_text(json.dumps(res, indent=1), encoding="utf-8")
            args.result = str(merged)
        res["result_path"] = os.path.relpath(args.result, ROOT)
        path = ROOT / "docs" / DOC
        path.write_text(report(res), encoding="utf-8")
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
