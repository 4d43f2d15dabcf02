"""OpenGL entry points that neither moderngl nor bpy's ``gpu`` expose, through ctypes: compile and
link logs with their warnings (``measure``) and the GLSL Blender compiled, read back from the
driver (``prepare``)."""

from __future__ import annotations

import ctypes


def gl_library(names, **restypes):
    """The first of the OpenGL libraries ``names`` that loads and has the entry points of
    ``restypes`` (name → ctypes return type, which is set), or None."""
    for name in names:
        try:
            lib = ctypes.CDLL(name)
            for fn, restype in restypes.items():
                getattr(lib, fn).restype = restype
            return lib
        except (OSError, AttributeError):
            continue
    return None


class GLSources:
    """The GLSL that Blender compiled, read back from the driver (OpenGL backend only): the
    shader objects that appear while ``fn`` runs, by stage."""

    GL_SHADER_TYPE = 0x8B4F
    STAGES = {0x8B31: "vertex", 0x8B30: "fragment"}

    def __init__(self):
        self.gl = gl_library(("libOpenGL.so.0", "libGL.so.1"), glIsShader=ctypes.c_ubyte)

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
        c = ctypes
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


class InfoLog:
    """Compile and link logs through the GL entry points (moderngl does not return the warnings of
    a successful compile); None where the library cannot be reached."""

    def __init__(self):
        self.gl = gl_library(
            ("libGL.so.1", "libOpenGL.so.0"), glCreateShader=ctypes.c_uint, glCreateProgram=ctypes.c_uint
        )

    def _log(self, get_iv, get_log, obj) -> str:
        c = ctypes
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
        gl, c = self.gl, ctypes
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
