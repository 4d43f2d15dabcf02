"""Meshes for the shaders: a mesh's arrays per face corner, and the GPU batch made from them."""

from __future__ import annotations

from dataclasses import dataclass, field

import bpy
import gpu
import numpy as np

from ...precompute.shading.transmit import Inside, mesh_inside
from .context import ensure_gpu_context


@dataclass(frozen=True)
class ImageTexture:
    """A Blender image read per pixel through Blender's own GPU texture of it
    (``gpu.texture.from_image``), looked up at each draw by name and library: painting the image,
    or setting its pixels from Python, shows on the next frame without a rebuild. Kept by name,
    not as the ``bpy.types.Image``, which an undo would leave dangling."""

    name: str
    library: str | None = None

    @classmethod
    def of(cls, image) -> ImageTexture:
        """The texture of ``image`` (a ``bpy.types.Image``), by name and library."""
        return cls(image.name, image.library.filepath if image.library is not None else None)

    def texture(self) -> gpu.types.GPUTexture | None:
        """The image's GPU texture now (its first channel scene linear: an 8-bit sRGB image
        decoded, Non-Color as stored; straight alpha), or None when the image is gone or empty."""
        image = bpy.data.images.get((self.name, self.library))
        if image is None or 0 in tuple(image.size):
            return None
        try:
            texture = gpu.texture.from_image(image)
        except (RuntimeError, SystemError, ValueError):
            return None
        # Its sampler as the shader's own maps (:func:`thickness_map_texture`), repeating as Image
        # Texture does: Blender turns anisotropic filtering on, and llvmpipe's then weighs even
        # magnified texels off the bilinear weights (2 % of the texels' step, measured); Blender's
        # own draws bind the texture with their own sampler states.
        texture.anisotropic_filter(False)
        texture.filter_mode(True)
        texture.extend_mode("REPEAT")
        return texture


def _per_vertex(name: str, values, count: int, width: int) -> np.ndarray:
    """``values`` as a contiguous float32 (count, width) array of one row per vertex; ValueError
    naming the attribute where there are not ``count`` rows."""
    array = np.ascontiguousarray(np.asarray(values, dtype=np.float32).reshape(-1, width))
    if array.shape[0] != count:
        raise ValueError(f"{name} {array.shape} must have one value per vertex ({count})")
    return array


@dataclass
class MeshBatch:
    """A triangle batch with attributes ``pos``, ``nor`` and optionally ``thickness`` (in [0, 1])
    and ``uv`` with the ``thickness_map`` read there per pixel (``TF_THICKNESS_MAP``): an R32F
    texture made from a map, or an :class:`ImageTexture` (:meth:`map_texture`).

    ``inside``: a thin transparent wall's mesh, whether it is closed and its thickness's linear fit
    (:func:`precompute.shading.transmit.mesh_inside`, asked for by ``from_arrays(..., wall=True)``);
    None: no reflections inside are drawn. ``bounds``: the positions' (2, 3) minimum and maximum,
    in the mesh's own space (where an instance's matrix places it)."""

    batch: gpu.types.GPUBatch
    vertex_count: int
    triangle_count: int
    has_thickness: bool
    inside: Inside | None = None
    bounds: np.ndarray | None = None  # set by from_arrays, the only maker
    thickness_map: gpu.types.GPUTexture | ImageTexture | None = None
    #: A noise computed per pixel from the positions (``TF_THICKNESS_NOISE``): the *Noise*
    #: source's (scale, seed), or a Noise Texture (``precompute.materials.perlin.NoiseSpec``: the
    #: *Blender Noise* source, a linked Noise Texture).
    noise: object = None
    #: (the noise's Color Ramp table, its texture) once :meth:`ramp_texture` made it.
    _ramp: tuple = field(default=((), None), repr=False, compare=False)

    @classmethod
    def from_arrays(
        cls, positions, normals, indices, thickness=None, wall: bool = False, thickness_map=None, orco=None
    ) -> MeshBatch | None:
        """Build from (V, 3) positions and normals, (F, 3) triangle indices, optional (V,) thickness;
        ``wall``: a thin transparent wall's, with its :attr:`inside` (a pass over its edges);
        ``thickness_map`` (with ``thickness``): (uv (V, 2), map (H, W) of parameters in [0, 1],
        repeat), uploaded as :attr:`thickness_map` (:func:`thickness_map_texture`), or (uv,
        :class:`ImageTexture`, repeat), read from Blender's texture at each draw. ``orco``: (V, 3)
        where the vertices were before a deformation, the attribute a Noise Texture at Generated
        coordinates reads (``TF_NOISE_ORCO``).

        Everything is converted to float32 / int32. Returns None for an empty mesh.
        """
        pos = np.ascontiguousarray(np.asarray(positions, dtype=np.float32).reshape(-1, 3))
        nor = np.ascontiguousarray(np.asarray(normals, dtype=np.float32).reshape(-1, 3))
        idx = np.ascontiguousarray(np.asarray(indices, dtype=np.int32).reshape(-1, 3))  # no copy if int32
        if pos.shape[0] == 0 or idx.shape[0] == 0:
            return None
        if nor.shape != pos.shape:
            raise ValueError(f"normals {nor.shape} must match positions {pos.shape}")
        if idx.min() < 0 or idx.max() >= pos.shape[0]:
            raise ValueError("triangle indices out of range")
        th = None if thickness is None else _per_vertex("thickness", thickness, pos.shape[0], 1)
        uv = None
        if thickness_map is not None and th is not None:
            uv = _per_vertex("uv", thickness_map[0], pos.shape[0], 2)
        orco = None if orco is None else _per_vertex("orco", orco, pos.shape[0], 3)
        attributes = {"pos": pos, "nor": nor, "thickness": th, "uv": uv, "orco": orco}
        attributes = {name: values for name, values in attributes.items() if values is not None}
        fmt = gpu.types.GPUVertFormat()
        for name, values in attributes.items():
            fmt.attr_add(id=name, comp_type="F32", len=values.shape[1], fetch_mode="FLOAT")
        ensure_gpu_context()
        vbo = gpu.types.GPUVertBuf(fmt, pos.shape[0])
        for name, values in attributes.items():
            vbo.attr_fill(name, values[:, 0] if values.shape[1] == 1 else values)
        th = None if th is None else th[:, 0]
        ibo = gpu.types.GPUIndexBuf(type="TRIS", seq=idx)
        batch = gpu.types.GPUBatch(type="TRIS", buf=vbo, elem=ibo)
        inside = mesh_inside(pos, idx, th) if wall else None
        columns = pos.T  # a column at a time: 8× faster than min(axis=0) over (V, 3) rows
        bounds = np.array([[c.min() for c in columns], [c.max() for c in columns]], dtype=np.float64)
        texture = None
        if uv is not None:
            texture = thickness_map[1]
            if not isinstance(texture, ImageTexture):
                texture = thickness_map_texture(texture, thickness_map[2])
        return cls(batch, pos.shape[0], idx.shape[0], th is not None, inside, bounds, texture)

    def map_texture(self) -> gpu.types.GPUTexture | None:
        """The texture the shader reads the thickness from now, or None (drawn per corner)."""
        found = self.thickness_map
        return found.texture() if isinstance(found, ImageTexture) else found

    def ramp_texture(self) -> gpu.types.GPUTexture | None:
        """The texture of the noise's Color Ramp table (``TF_THICKNESS_RAMP``), made once per
        table, or None where the noise has no ramp."""
        table = getattr(self.noise, "ramp", ())
        if not table:
            return None
        if self._ramp[0] is not table and self._ramp[0] != table:
            self._ramp = (table, ramp_texture(table))
        return self._ramp[1]


def thickness_map_texture(values, repeat: bool = False) -> gpu.types.GPUTexture:
    """An (H, W) map of thickness parameters as an R32F texture (row 0 at v = 0), filtered
    bilinearly, its edges repeated or extended (:data:`.layout.THICKNESS_MAP_SAMPLER`)."""
    data = np.ascontiguousarray(
        np.clip(np.nan_to_num(np.asarray(values, dtype=np.float32), nan=0.5), 0.0, 1.0)
    )
    if data.ndim != 2 or min(data.shape) < 1:
        raise ValueError(f"a thickness map must be (H, W), got {data.shape}")
    h, w = data.shape
    ensure_gpu_context()
    texture = gpu.types.GPUTexture((w, h), format="R32F", data=gpu.types.Buffer("FLOAT", w * h, data.ravel()))
    texture.filter_mode(True)
    texture.extend_mode("REPEAT" if repeat else "EXTEND")
    return texture


def ramp_texture(table) -> gpu.types.GPUTexture:
    """A Color Ramp's table (``precompute.materials.ramp``: (N,) values at 0 … 1) as an N × 1
    R32F texture, read entry by entry (:data:`.layout.THICKNESS_RAMP_SAMPLER`, texelFetch)."""
    data = np.ascontiguousarray(np.nan_to_num(np.asarray(table, dtype=np.float32).reshape(-1)))
    if data.size < 2:
        raise ValueError(f"a ramp table needs at least 2 entries, got {data.size}")
    ensure_gpu_context()
    buffer = gpu.types.Buffer("FLOAT", data.size, data)
    return gpu.types.GPUTexture((data.size, 1), format="R32F", data=buffer)


def corner_vertices(mesh) -> np.ndarray:
    """Each face corner's vertex index (N,) int32, read through the mesh's ``.corner_vert``
    attribute in one block (:func:`_attribute_array`)."""
    n_loop = len(mesh.loops)
    loop_vert = _attribute_array(mesh, ".corner_vert", "CORNER", "INT", n_loop, np.int32)
    if loop_vert is None:
        loop_vert = np.empty(n_loop, dtype=np.int32)
        mesh.loops.foreach_get("vertex_index", loop_vert)
    return loop_vert


def vertex_positions(mesh) -> np.ndarray:
    """Each vertex's object-space position (V, 3) float32, read through the mesh's ``position``
    attribute in one block."""
    co = _attribute_array(mesh, "position", "POINT", "FLOAT_VECTOR", 3 * len(mesh.vertices), np.float32)
    if co is None:
        co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def corner_positions(mesh, loop_vert=None) -> np.ndarray:
    """Each face corner's object-space position (N, 3) float32 (:func:`vertex_positions`);
    ``loop_vert``: :func:`corner_vertices`, read if None."""
    loop_vert = corner_vertices(mesh) if loop_vert is None else loop_vert
    return np.take(vertex_positions(mesh), loop_vert, axis=0)  # half the time of co[loop_vert]


#: A quad's two triangles' corners within it: split along its first diagonal (0–2), or along
#: its second (1–3) where Blender flips it.
_QUAD_SPLITS = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
_FLIPPED_SPLITS = np.array([[0, 1, 3], [1, 2, 3]], dtype=np.int32)


def triangle_corners(mesh, positions=None, loop_vert=None) -> np.ndarray:
    """(T, 3) int32 corner indices of ``mesh.loop_triangles``, in their order, equal to what
    ``foreach_get("loops")`` reads (one RNA item at a time: 145 ms for 1.6 M triangles). Where
    every face is a triangle or a quad they are worked out from ``loop_triangle_polygons`` (an
    array copy) as Blender's tessellation makes them (``mesh_tessellate.cc``): a quad is split
    along 0–2 unless that diagonal lies outside it (Blender's flip test, :func:`_quad_flips`),
    then along 1–3. ``positions`` (:func:`vertex_positions`) and ``loop_vert``
    (:func:`corner_vertices`) are read if None and a quad needs them. Meshes with n-gons
    (polyfill) are read from RNA. Call ``mesh.calc_loop_triangles()`` first where they may be
    missing."""
    n_tri = len(mesh.loop_triangles)
    faces = np.empty(n_tri, dtype=np.int32)
    mesh.loop_triangle_polygons.foreach_get("value", faces)  # each face's triangles in a row
    per_face = np.bincount(faces, minlength=len(mesh.polygons)).astype(np.int32)
    if n_tri == 0 or per_face.min() < 1 or per_face.max() > 2 or n_tri + 2 * per_face.size != len(mesh.loops):
        corners = np.empty(3 * n_tri, dtype=np.int32)  # n-gons (or counts that disagree)
        mesh.loop_triangles.foreach_get("loops", corners)
        return corners.reshape(-1, 3)
    out = np.empty((n_tri, 3), dtype=np.int32)
    quads = np.flatnonzero(per_face == 2)
    if quads.size:
        positions = vertex_positions(mesh) if positions is None else positions
        loop_vert = corner_vertices(mesh) if loop_vert is None else loop_vert
    if quads.size == per_face.size:  # quads only (a Subdivision Surface's): views, no gathers
        starts = np.arange(0, len(mesh.loops), 4, dtype=np.int32)
        _split_quads(out.reshape(-1, 2, 3), starts, loop_vert.reshape(-1, 4), positions)
        return out
    sizes = per_face + 2
    face_start = np.cumsum(sizes, dtype=np.int32) - sizes
    first_tri = np.cumsum(per_face, dtype=np.int32) - per_face
    triangles = np.flatnonzero(per_face == 1)
    out[first_tri[triangles]] = face_start[triangles, None] + _QUAD_SPLITS[0]
    if quads.size:
        starts = face_start[quads]
        verts = np.take(loop_vert, starts[:, None] + np.arange(4, dtype=np.int32))
        split = np.empty((quads.size, 2, 3), dtype=np.int32)
        _split_quads(split, starts, verts, positions)
        at = first_tri[quads]
        out[at], out[at + 1] = split[:, 0], split[:, 1]
    return out


def _split_quads(out, starts, verts, positions) -> None:
    """Fill ``out`` (Q, 2, 3) with the triangles of the quads whose first corners are ``starts``
    and whose vertices are ``verts`` (Q, 4), at ``positions`` (V, 3)."""
    columns = np.ascontiguousarray(np.asarray(positions, dtype=np.float32).T)  # (3, V)
    flip = np.flatnonzero(_quad_flips([np.take(columns, verts[:, i], axis=1) for i in range(4)]))
    np.add(starts[:, None, None], _QUAD_SPLITS, out=out)
    out[flip] = starts[flip, None, None] + _FLIPPED_SPLITS


def _quad_flips(corners) -> np.ndarray:
    """Whether Blender splits each quad along 1–3 (``corners``: its four corners' positions,
    each (3, Q) float32): the normals of triangles (0, 1, 2) and (0, 3, 2) point the same way,
    so 0–2 lies outside the quad. In float32, each product and sum in Blender's order
    (math_geom's first/third test), so a quad flips exactly where Blender's does."""
    p0 = corners[0]
    (x1, y1, z1), (x2, y2, z2), (x3, y3, z3) = (corners[i] - p0 for i in (1, 2, 3))
    a = (y1 * z2 - z1 * y2, z1 * x2 - x1 * z2, x1 * y2 - y1 * x2)  # (p1 − p0) × (p2 − p0)
    b = (y3 * z2 - z3 * y2, z3 * x2 - x3 * z2, x3 * y2 - y3 * x2)  # (p3 − p0) × (p2 − p0)
    return (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) > np.float32(0.0)


def _attribute_array(mesh, name: str, domain: str, data_type: str, size: int, dtype):
    """A mesh attribute's values read in one block, or None where the attribute is not there.

    ``foreach_get`` on the attribute copies the array; on ``mesh.loops`` / ``mesh.vertices`` it
    goes through RNA item by item, far slower (docs/tuning.md#mesh-attributes).
    """
    attr = mesh.attributes.get(name)
    if attr is None or attr.domain != domain or attr.data_type != data_type:
        return None
    out = np.empty(size, dtype=dtype)
    attr.data.foreach_get("vector" if data_type == "FLOAT_VECTOR" else "value", out)
    return out


def vertex_arrays(mesh, corner_values=None):
    """(positions (V, 3), normals (V, 3), triangles (T, 3) into them, ``corner_values`` per
    vertex or None) of a mesh whose normals are its vertices' (``normals_domain`` POINT: shaded
    smooth, no sharp edges or custom normals), else None: a batch then shares each vertex
    between its corners, a quarter of :func:`mesh_arrays`' per-corner rows for a quad mesh,
    drawn the same. None also for a mesh without triangles, with loose vertices, or where two
    corners of a vertex have different ``corner_values`` (:func:`vertex_values`; checked before
    the triangles are worked out)."""
    if mesh.normals_domain != "POINT":
        return None
    if len(mesh.loop_triangles) == 0:
        mesh.calc_loop_triangles()
    if len(mesh.loop_triangles) == 0 or len(mesh.vertices) == 0:
        return None
    loop_vert = corner_vertices(mesh)
    used = np.zeros(len(mesh.vertices), dtype=bool)
    used[loop_vert] = True
    if not used.all():  # loose vertices: the batch's bounds would take them in
        return None
    values = None
    if corner_values is not None:
        values = vertex_values(corner_values, loop_vert, len(mesh.vertices))
        if values is None:
            return None
    positions = vertex_positions(mesh)
    normals = np.empty(positions.size, dtype=np.float32)
    mesh.vertex_normals.foreach_get("vector", normals)
    triangles = np.take(loop_vert, triangle_corners(mesh, positions, loop_vert))
    return positions, normals.reshape(-1, 3), triangles, values


def vertex_values(values, loop_vert, count: int) -> np.ndarray | None:
    """``values`` given per face corner (N, ...) as one per vertex (``count``, ...), or None where
    two corners of a vertex differ (a UV seam, a face attribute): the batch of
    :func:`vertex_arrays` can carry them only where they agree (NaN equal to NaN)."""
    values = np.asarray(values)
    per_vertex = np.zeros((count, *values.shape[1:]), dtype=values.dtype)
    per_vertex[loop_vert] = values
    same = np.array_equal(np.take(per_vertex, loop_vert, axis=0), values, equal_nan=True)
    return per_vertex if same else None


def mesh_arrays(mesh, thickness_attribute: str | None = None):
    """(positions, normals, triangles, thickness | None) of a mesh, one vertex per face corner.

    Positions and split/custom normals (``mesh.corner_normals``) per corner (loop), triangles
    from the loop triangulation as corner indices, and the named FLOAT attribute (point, corner
    or face domain) per corner, raw (the caller maps it to [0, 1]); None when it is missing or of
    another type. Returns None for a mesh without triangles.
    """
    tris = mesh.loop_triangles
    if len(tris) == 0:
        mesh.calc_loop_triangles()
        tris = mesh.loop_triangles
    n_tri, n_loop = len(tris), len(mesh.loops)
    if n_tri == 0 or n_loop == 0:
        return None
    loop_vert = corner_vertices(mesh)
    co = vertex_positions(mesh)
    positions = np.take(co, loop_vert, axis=0)
    normals = np.empty(n_loop * 3, dtype=np.float32)
    mesh.corner_normals.foreach_get("vector", normals)
    triangles = triangle_corners(mesh, co, loop_vert)
    thickness = None
    if thickness_attribute:
        attr = mesh.attributes.get(thickness_attribute)
        if attr is not None and attr.data_type == "FLOAT":
            values = np.empty(len(attr.data), dtype=np.float32)
            attr.data.foreach_get("value", values)
            if attr.domain == "POINT":
                thickness = np.take(values, loop_vert)
            elif attr.domain == "CORNER":
                thickness = values
            elif attr.domain == "FACE":
                totals = np.empty(len(mesh.polygons), dtype=np.int32)
                mesh.polygons.foreach_get("loop_total", totals)
                thickness = np.repeat(values, totals)  # polygons own consecutive loop ranges
    return positions, normals.reshape(-1, 3), triangles, thickness
