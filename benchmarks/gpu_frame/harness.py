"""The moderngl side: GLSL as Blender's OpenGL backend declares it, the GPU objects of a prepared
OUTDIR, and frames drawn and timed from them.

numpy + moderngl only (no bpy, no add-on, no precompute): this runs on the GPU machine.
"""

from __future__ import annotations

import time

import moderngl
import numpy as np

from .gl import InfoLog
from .store import Prepared

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


def create_context(backend: str | None):
    kwargs = {"require": 430}
    if backend:
        kwargs["backend"] = backend
    return moderngl.create_standalone_context(**kwargs)


class Harness:
    """GPU objects of a prepared OUTDIR in one moderngl context, and frames drawn from them."""

    def __init__(self, prepared: Prepared, ctx, sources: str = "header", log=print):
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
        infolog = InfoLog()
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
        if res["dim"] == "2d_array" and res.get("format") == "RGBA16F":  # the radiance grid
            layers, h, w = a.shape[:3]
            tex = self.ctx.texture_array((w, h, layers), 4, a.astype(np.float16).tobytes(), dtype="f2")
        elif res["dim"] == "2d_array":
            layers, h, w = a.shape[:3]
            tex = self.ctx.texture_array((w, h, layers), 4, a.tobytes(), dtype="f4")
        elif res["dim"] == "3d":
            d, h, w = a.shape[:3]
            tex = self.ctx.texture3d((w, h, d), 4, a.tobytes(), dtype="f4")
        else:
            h, w = a.shape[:2]
            tex = self.ctx.texture((w, h), 4, a.tobytes(), dtype="f4")
        if role in ("prefiltered", "grid"):  # PrefilterTexture, RadianceGridTexture: LINEAR, REPEAT in x
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
        for role, ubo_slot, tex_slot in (
            ("table", 3, 0),
            ("film", 4, 4),
            ("prefiltered", None, 3),
            ("grid", None, 6),  # gpu.layout.RADIANCE_GRID_SAMPLER
        ):
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
        """Clear and draw one case into ``fbo`` (as gpu.draw.submit, see the module docstring)."""
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
