"""Recording what the extension draws (bpy): create-info stand-ins, the capture of uploads and
meshes, the manifest writer, and the benchmark scenes of benchmarks/viewport/ case by case."""

from __future__ import annotations

import hashlib
from dataclasses import replace

import numpy as np

from .. import viewport as vp
from .config import (
    LAMPS,
    LAMPS_ON_ONLY,
    LOOP_CASES_L,
    REFERENCE_ROTATION,
    SCENES,
    TEXTURE_CASES_L,
    TEXTURE_CASES_SCENES,
    case_id,
)
from .store import ArrayStore, digest


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
            raise ValueError(f"create-info call {name}{args} {kwargs} is not known to benchmarks.gpu_frame")
        if name == "define":
            out["defines"].append([args[0], args[1] if len(args) > 1 else ""])
        elif name == "typedef_source":
            out["typedefs"].append(source_key(sources, args[0]))
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
                    raise ValueError(f"interface call {call}{margs} is not known to benchmarks.gpu_frame")
                members.append([call, margs[0], margs[1]])
            out["interfaces"].append({"name": stage.args[0], "members": members})
        elif name == "fragment_out":
            out["fragment_out"].append([int(args[0]), args[1], args[2]])
        elif name == "vertex_source":
            out["vertex_source"] = source_key(sources, args[0])
        elif name == "fragment_source":
            out["fragment_source"] = source_key(sources, args[0])
    if iface is not None and not any(i["name"] == iface.args[0] for i in out["interfaces"]):
        raise ValueError("the stage interface was made but not used")
    return out


def source_key(sources: dict, text: str) -> str:
    key = "s" + hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]
    sources.setdefault(key, text)
    return key


class _NamedVariant:
    """A recorded variant under another name (the loop rotation of :class:`Capture`)."""

    def __init__(self, variant, name: str):
        self.variant, self.name = variant, name


def variant_key(variant) -> str:
    """A readable name of a ``Variant``: l, then the flags that are set."""
    if isinstance(variant, _NamedVariant):
        return variant.name
    flags = [name for name, value in variant._asdict().items() if name != "l_max" and value]
    return "-".join([f"l{variant.l_max}", *flags])


class Capture:
    """Records, while active, what the GPU layer (``addon.gpu``, its modules imported) uploads and
    compiles, through stand-ins:

    - ``gpu.types.GPUTexture`` / ``GPUUniformBuf`` as seen from ``gpu.resources``: the real object
      is made and returned, its data kept by ``id`` (every table, film, lighting and prefiltered
      World);
    - ``MeshBatch.from_arrays`` (``gpu.mesh``): the arrays of each batch, by ``id`` of its GPUBatch;
    - a ``ShaderCache`` whose ``_compile`` records the variant's create-info instead of compiling
      (``gpu.shaders.mesh_shader_info`` runs with create-info recorders in place of gpu.types's);
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

        class Shaders(gd.shaders.ShaderCache):
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

        class LoopShaders(gd.shaders.ShaderCache):
            """The reference rotation's generic loops (tests/glsl/), recorded as "<variant>-loops"."""

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
        self.loop_shaders = LoopShaders(reference_rotation=REFERENCE_ROTATION)
        self.uniforms = Uniforms()

    def create_info(self, make_info) -> dict:
        shaders = self.gd.shaders
        real = shaders.gpu
        types = _Namespace(real.types, GPUShaderCreateInfo=_Recorder, GPUStageInterfaceInfo=_Recorder)
        shaders.gpu = _Namespace(real, types=types)
        try:
            info, iface = make_info()
        finally:
            shaders.gpu = real
        return _create_info_dict(info, iface, self.sources)

    def __enter__(self):
        gd, capture = self.gd, self
        real = gd.resources.gpu

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
        gd.resources.gpu = _Namespace(
            real, types=_Namespace(real.types, GPUTexture=texture, GPUUniformBuf=uniform_buf)
        )
        self._from_arrays = gd.mesh.MeshBatch.__dict__["from_arrays"]
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

        gd.mesh.MeshBatch.from_arrays = classmethod(from_arrays)
        return self

    def __exit__(self, *exc):
        self.gd.resources.gpu = self._real_gpu
        self.gd.mesh.MeshBatch.from_arrays = self._from_arrays
        return False


class _Uniform:
    """What the recording uniform cache hands to ``prepare_draw`` in place of a GPUUniformBuf."""

    def __init__(self, data: np.ndarray):
        self.data = data


class Writer:
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
        if rec["format"] not in ("RGBA32F", "RGBA16F") or rec["data"] is None:
            raise RuntimeError(f"{role}: texture {rec['format']} without data is not supported")
        if layers:
            shape, dim = (layers, size[1], size[0], 4), "2d_array"
        elif len(size) == 3:
            shape, dim = (size[2], size[1], size[0], 4), "3d"
        else:
            shape, dim = (size[1], size[0], 4), "2d"
        out = {"kind": "texture", "dim": dim, "array": self.store.add(rec["data"].reshape(shape))}
        if rec["format"] == "RGBA16F":  # the radiance grid: uploaded as half floats (harness.texture)
            out["format"] = "RGBA16F"
        return out

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
        key = "m" + digest(vertices)[:8] + digest(rec["indices"])[:8]
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
                    "positions": digest(rec["positions"]),
                    "normals": digest(rec["normals"]),
                    "indices": digest(idx),
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
            packed = gd.resources.Lighting.pack(
                by_lighting[id(group.lighting)].coefficients, by_lighting[id(group.lighting)].lamps
            )
            if digest(packed.astype(np.float32)) != digest(self.store.get(lighting["array"])):
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
                    "grid": None if getattr(group, "grid", None) is None else self.upload(group.grid, "grid"),
                    "draws": [[self.mesh(batch), self.store.add(ubo.data)] for batch, ubo, *_ in group.draws],
                }
            )
        return {**meta, "view": self.store.add(prepared.view.data), "groups": groups}


def _automatic_frames(scene, size, scene_name: str, spec: dict):
    """The ``automatic`` scene: glossy, medium and rough films at their automatic order (lamps on),
    as the product draws them and (medium, rough) with the per-pixel SH (case "<film>-perpixel")."""
    import bpy

    objects, triangles = spec["layout"]
    scene.set_objects(objects, triangles)
    frame = None
    try:
        for case in spec["cases"]:
            rough = vp.AUTOMATIC_ROUGHNESS[case]
            mat = bpy.data.materials.get(f"Film auto {case}")
            if mat is None:
                mat = bpy.data.materials.new(f"Film auto {case}")
                scene.ext.conversion.fill_from_material(mat.thinfilm_sh, vp.FILM.with_(roughness=rough))
                mat.thinfilm_sh.sh_order = "AUTO"
                mat.thinfilm_sh.enabled = True
            for obj in scene.objects:
                obj.data.materials.clear()
                obj.data.materials.append(mat)
            bpy.context.view_layer.update()
            scene.ext.scene_draw.collect(bpy.context.evaluated_depsgraph_get())  # bake, World, grid
            if frame is None:
                frame = vp.Frame(scene, *size)
            items = frame.items()
            l_max = int(items[0].table.l_max)
            meta = {
                "id": case_id(scene_name, l_max, case, True),
                "scene": scene_name,
                "l_max": l_max,
                "case": case,
                "lamps": True,
                "roughness": rough,
                "objects": objects,
                "triangles": scene.triangles,
                "sh_weight": float(items[0].sh_weight),
                "split_used": items[0].prefiltered is not None and items[0].sh_weight < 1.0,
                "lamp_count": int(items[0].lighting.lamp_count),
                "radiance_grid": items[0].grid is not None,
            }
            tex = _textures_only(items) or items  # as a hardware GPU reads the table
            yield meta, tex, frame.base_view, frame.proj
            if items[0].grid is not None:
                per_pixel = [replace(it, grid=None) for it in tex]
                yield (
                    dict(meta, id=case_id(scene_name, l_max, case + "-perpixel", True), radiance_grid=False),
                    per_pixel,
                    frame.base_view,
                    frame.proj,
                )
    finally:
        if frame is not None:
            frame.free()


def _frames(scene, size):
    """The scene's cases: (meta, items, view, projection), as benchmarks/viewport/ draws them."""
    rough = vp.roughness_cases()
    for scene_name, spec in SCENES.items():
        if scene_name in LAMPS_ON_ONLY:
            yield from _automatic_frames(scene, size, scene_name, spec)
            continue
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
    hardware GPU draws them (``policy.TABLE_UBO_DEVICES``: only software rasterisers, where
    ``prepare`` runs, use the uniform buffer), or None where the table already is a texture. The
    lamps' film table keeps its uniform buffer, as on every device."""
    if not any(it.table.ubo is not None for it in items):
        return None
    return [replace(it, table=replace(it.table, ubo=None)) for it in items]


def _check_constants() -> None:
    if tuple(SCENES["sweep"]["layout"]) != tuple(vp.SWEEP_SCENE):
        raise RuntimeError(f"viewport.SWEEP_SCENE is {vp.SWEEP_SCENE}, this harness has {SCENES['sweep']}")
    if tuple(SCENES["sweep"]["l_max"]) != tuple(vp.SPLIT_SUM_L):
        raise RuntimeError(f"viewport.SPLIT_SUM_L is {vp.SPLIT_SUM_L}, this harness has {SCENES['sweep']}")


def record_cases(size, log=print):
    """Set up the scenes (bpy) and yield (meta, items, view, projection, capture) per case, with the
    capture active; the extension instance is created here."""
    _check_constants()
    ext = vp.Extension()
    capture = Capture(ext.gpu)
    ext.scene_draw.CACHES.clear()
    with capture:
        scene = vp.Scene(ext)
        for meta, items, view, proj in _frames(scene, size):
            yield meta, items, view, proj, capture, ext
