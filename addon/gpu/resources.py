"""The GPU objects the shaders read, made from arrays: textures, uniform buffers, their caches.

:class:`TableTexture`, :class:`FilmTexture`, :class:`PrefilterTexture`,
:class:`EnvironmentTexture`, :class:`DisplayLUTTexture`, :class:`RadianceGridTexture`,
:class:`BehindTexture`; :class:`Lighting` (the World's SH for one material, in
:data:`.layout.LIGHTING`), :class:`UniformCache` (view and object buffers kept across frames),
:func:`lights_content` and :func:`float_buffer`. The buffers' layouts and the binding slots are
:mod:`.layout`'s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gpu
import numpy as np

from ...precompute.colour import display_lut
from ...precompute.shading import policy, radiance_grid
from ...precompute.shading.codegen import x_rotation_scalars
from ...precompute.shading.lights import LIGHT_VEC4, Lights
from ...precompute.shading.variant import fits_uniform_buffer
from .context import ensure_gpu_context
from .layout import BEHIND, FILM, LAMP_VEC4, LIGHTING, LIGHTS, MAX_L, MAX_LAMPS, MAX_LIGHTS, TABLE, Block


# ----------------------------------------------------------------------------------------------
# Data on the GPU
# ----------------------------------------------------------------------------------------------
def float_buffer(array) -> gpu.types.Buffer:
    """A flat FLOAT Buffer from any array (converted to contiguous float32 first)."""
    data = np.ascontiguousarray(np.asarray(array, dtype=np.float32).ravel())
    return gpu.types.Buffer("FLOAT", data.size, data)


def uses_table_ubo(device_type: str) -> bool:
    """Whether a device of this ``gpu.platform.device_type_get()`` type draws tables from the
    uniform buffer (policy.TABLE_UBO_DEVICES)."""
    return str(device_type).upper() in policy.TABLE_UBO_DEVICES


def table_ubo_preferred() -> bool:
    """:func:`uses_table_ubo` for the GPU Blender draws with."""
    ensure_gpu_context()
    return uses_table_ubo(gpu.platform.device_type_get())


def texel_block(block: Block, layers: np.ndarray) -> np.ndarray | None:
    """:data:`TABLE` or :data:`FILM` content from (layers, rows, columns, 4) texture content, or None
    when it does not fit (variant.fits_uniform_buffer)."""
    n_layers, rows, columns = layers.shape[:3]
    if not fits_uniform_buffer(n_layers, rows, columns):
        return None
    return block.pack(size=(columns, rows, n_layers, 0), texel=layers.transpose(1, 2, 0, 3))


@dataclass
class TableTexture:
    """A baked table on the GPU and its metadata.

    ``texture`` (:data:`TABLE_SAMPLER`, RGBA32F): width A = view angles θo (uniform 0…90°
    inclusive), height T = thickness rows, one layer per table row: spectral tables have 3 layers
    per kept coefficient i (layer 3i + k = row k of the 3×3 matrix, .rgb = lighting RGB),
    per-channel tables 1 (layer i = the RGB factors). The shader interpolates with ``texelFetch``
    in full float32 (tf_table.glsl), so the texture's filter mode is irrelevant.
    """

    texture: gpu.types.GPUTexture
    l_max: int
    view_samples: int
    thickness_count: int
    spectral: bool
    layers: int
    #: The same texels as a :data:`TABLE` uniform buffer when they fit (:meth:`uniform_array`).
    ubo: gpu.types.GPUUniformBuf | None = None

    @staticmethod
    def uniform_array(layers: np.ndarray) -> np.ndarray | None:
        """:data:`TABLE` content (1024 × 4 float32) from :meth:`layer_array`'s output, or None when
        layers × T × A exceeds UBO_TEXELS."""
        return texel_block(TABLE, layers)

    @staticmethod
    def layer_array(data) -> np.ndarray:
        """(layers, T, A, 4) float32 texture content from a table (T, A, K, 3[, 3])."""
        data = np.asarray(data, dtype=np.float32)
        t, a, k = data.shape[:3]
        if data.ndim == 5:  # (T, A, K, 3 out, 3 light) → layer 3i + out
            rows = data.transpose(2, 3, 0, 1, 4).reshape(3 * k, t, a, 3)
        elif data.ndim == 4:
            rows = data.transpose(2, 0, 1, 3)
        else:
            raise ValueError(f"table data must be (T, A, K, 3) or (T, A, K, 3, 3), got {data.shape}")
        out = np.zeros(rows.shape[:3] + (4,), dtype=np.float32)
        out[..., :3] = rows
        return out

    @classmethod
    def from_result(cls, result, *, uniform: bool | None = None) -> TableTexture:
        """Upload a :class:`precompute.bakes.bake.BakeResult` (or anything with ``data``, ``sh_order``).

        ``uniform``: also make the uniform-buffer copy when the table fits (drawn from there);
        None (default): where this device draws faster from it (:func:`table_ubo_preferred`).
        """
        if uniform is None:
            uniform = table_ubo_preferred()
        data = np.asarray(result.data)
        l_max = int(result.sh_order)
        if not 0 <= l_max <= MAX_L:
            raise ValueError(f"sh_order must lie in 0…{MAX_L}, got {l_max}")
        kept = (l_max + 1) * (l_max + 2) // 2
        if data.ndim not in (4, 5) or data.shape[2] != kept or data.shape[3] != 3:
            raise ValueError(
                f"table of shape {data.shape} does not match sh_order {l_max} ({kept} coefficients)"
            )
        if data.shape[1] < 2:
            raise ValueError("the table needs at least 2 view angles")
        if not np.all(np.isfinite(data)):
            raise ValueError("the table holds non-finite values")
        layers = cls.layer_array(data)
        ensure_gpu_context()
        n_layers, t, a = layers.shape[:3]
        limit = gpu.capabilities.max_texture_layers_get()
        if n_layers > limit:
            raise ValueError(f"{n_layers} table layers exceed this GPU's limit of {limit}")
        texture = gpu.types.GPUTexture((a, t), layers=n_layers, format="RGBA32F", data=float_buffer(layers))
        packed = cls.uniform_array(layers) if uniform else None
        ubo = gpu.types.GPUUniformBuf(float_buffer(packed)) if packed is not None else None
        return cls(texture, l_max, a, t, data.ndim == 5, n_layers, ubo)


@dataclass
class Lighting:
    """The World's radiance SH, windowed for one material, in a :data:`LIGHTING` buffer with the
    rotation constants."""

    ubo: gpu.types.GPUUniformBuf
    coefficients: np.ndarray  # ((l_max+1)², 3) float64, windowed: what the shader sees
    l_max: int
    roughness: float
    #: The World's lamps (precompute.world.lamps.Lamps) the coefficients were taken without, or None.
    lamps: object = None

    @property
    def lamp_count(self) -> int:
        """Number of World lamps drawn (0 without a lamp set)."""
        return 0 if self.lamps is None else int(self.lamps.count)

    @staticmethod
    def pack(coefficients, lamps=None, rotation=None, scale: float = 1.0) -> np.ndarray:
        """:data:`LIGHTING` content, flat float32, for windowed coefficients (≤ SH_SLOTS, 3), up
        to MAX_LAMPS lamps, and the World's turn Q (3×3, None: identity) and strength ``scale``
        the prefilter lookup applies (``prefilter.Prefiltered.transformed``)."""
        c = np.asarray(coefficients, dtype=np.float64)
        sh_rows = np.zeros((c.shape[0], 4), dtype=np.float64)
        sh_rows[:, :3] = c[:, :3]
        lamp_rows = np.zeros((LAMP_VEC4, 4), dtype=np.float64)
        if lamps is not None and lamps.count:
            if lamps.count > MAX_LAMPS:
                raise ValueError(f"{lamps.count} lamps exceed the shader's {MAX_LAMPS}")
            if not (np.all(np.isfinite(lamps.directions)) and np.all(np.isfinite(lamps.power))):
                raise ValueError("lamp directions and power must be finite")
            lamp_rows[0, 0] = lamps.count
            lamp_rows[1 : 1 + 2 * lamps.count : 2, :3] = lamps.directions
            lamp_rows[2 : 2 + 2 * lamps.count : 2, :3] = lamps.power
        turn = np.zeros((3, 4), dtype=np.float64)
        turn[:, :3] = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64).reshape(3, 3)
        turn[0, 3] = float(scale)
        if not np.all(np.isfinite(turn)):
            raise ValueError("the World's rotation and strength must be finite")
        return LIGHTING.pack(sh=sh_rows, lamps=lamp_rows, rx=x_rotation_scalars(), world=turn).reshape(-1)

    @classmethod
    def from_sh(
        cls, world_coeffs, l_max: int, roughness: float, lamps=None, rotation=None, scale: float = 1.0
    ) -> Lighting:
        """World SH (≥ 1, 3) → windowed by policy.lighting_window for ``l_max``/``roughness``.

        Missing coefficients (fewer than (l_max+1)²) are zero; extra ones are dropped.
        ``lamps``: the World's lamps, when ``world_coeffs`` are those of the World without them.
        ``rotation``, ``scale``: the World's turn and strength for the prefilter lookup (the SH
        and lamps given are already in the World's frame and strength).
        """
        l_max = int(l_max)
        if not 0 <= l_max <= MAX_L:
            raise ValueError(f"l_max must lie in 0…{MAX_L}, got {l_max}")
        c = np.asarray(world_coeffs, dtype=np.float64)
        if c.ndim != 2 or c.shape[1] < 3 or not np.all(np.isfinite(c)):
            raise ValueError(f"world_coeffs must be finite, shape (K, 3), got {c.shape}")
        windowed = policy.windowed_lighting(c, l_max, roughness)
        ensure_gpu_context()
        ubo = gpu.types.GPUUniformBuf(float_buffer(cls.pack(windowed, lamps, rotation, scale)))
        return cls(
            ubo, windowed, l_max, float(roughness), lamps if lamps is not None and lamps.count else None
        )


@dataclass
class EnvironmentTexture:
    """The World's equirect image (H, W, C ≥ 3, top row first) as a texture
    (:data:`ENVIRONMENT_SAMPLER`, RGBA32F): hardware LINEAR filtering, REPEAT in u, EXTEND in v."""

    texture: gpu.types.GPUTexture
    width: int
    height: int

    @classmethod
    def from_image(cls, image) -> EnvironmentTexture:
        """Upload an (H, W, 3|4) float image as an RGBA32F equirectangular texture."""
        img = np.asarray(image, dtype=np.float32)
        if img.ndim != 3 or img.shape[2] < 3:
            raise ValueError(f"environment image must be (H, W, 3|4), got {img.shape}")
        h, w = img.shape[:2]
        rgba = np.ones((h, w, 4), dtype=np.float32)
        rgba[..., :3] = img[..., :3]
        ensure_gpu_context()
        texture = gpu.types.GPUTexture((w, h), format="RGBA32F", data=float_buffer(rgba))
        texture.filter_mode(True)
        texture.extend_mode_x("REPEAT")
        texture.extend_mode_y("EXTEND")
        return cls(texture, w, h)


@dataclass
class PrefilterTexture:
    """The World prefiltered by GGX at J roughness levels and their direction moments.

    ``texture`` (:data:`PREFILTERED_SAMPLER`, RGBA32F, LINEAR, REPEAT in u, EXTEND in v and z):
    a 3-D texture of depth 2J, equirect slices top row first; slice j < J = the World prefiltered
    at the roughness of level j (policy.ROUGHNESS_LEVELS), slice J + j = the same prefilter of
    luminance × direction (the moment; zero when not given). A 3-D texture rather than an array,
    so the blend of two levels is one linear fetch (docs/tuning.md#prefilter-texture).
    """

    texture: gpu.types.GPUTexture
    levels: int
    width: int
    height: int

    @classmethod
    def from_levels(cls, levels, moments=None) -> PrefilterTexture:
        """From (J, H, W, 3) radiance, J ≥ 2 levels at roughness (j / (J − 1))², top row first.

        ``moments``: the levels' luminance × direction prefilter, same shape
        (prefilter.Prefiltered.resampled_moments), stored as layers J … 2J − 1; None stores
        zeros, and the shader then reads the film's albedo at the view angle.
        """
        return cls.from_packed(cls.pack(levels, moments))

    @staticmethod
    def pack(levels, moments=None) -> np.ndarray:
        """The texture's content (2J, H, W, 4) float32 (:meth:`from_levels`' layout), checked:
        numpy only, so a worker thread can make it and the main thread only uploads it."""
        data = np.asarray(levels, dtype=np.float32)
        if data.ndim != 4 or data.shape[0] < 2 or data.shape[3] < 3:
            raise ValueError(f"prefiltered levels must be (J ≥ 2, H, W, 3), got {data.shape}")
        if not np.all(np.isfinite(data)):
            raise ValueError("prefiltered levels contain NaN or Inf")
        j = data.shape[0]
        rgba = np.zeros((2 * j,) + data.shape[1:3] + (4,), dtype=np.float32)
        rgba[:j, ..., :3] = data[..., :3]
        if moments is not None:
            mom = np.asarray(moments, dtype=np.float32)
            if mom.shape[:3] != data.shape[:3] or mom.shape[3] < 3:
                raise ValueError(f"prefiltered moments must be {data.shape[:3] + (3,)}, got {mom.shape}")
            if not np.all(np.isfinite(mom)):
                raise ValueError("prefiltered moments contain NaN or Inf")
            rgba[j:, ..., :3] = mom[..., :3]
        return rgba

    @classmethod
    def from_packed(cls, rgba) -> PrefilterTexture:
        """Upload :meth:`pack`'s (2J, H, W, 4) float32 array (the main thread's only share)."""
        rgba = np.asarray(rgba, dtype=np.float32)
        if rgba.ndim != 4 or rgba.shape[0] < 4 or rgba.shape[0] % 2 or rgba.shape[3] != 4:
            raise ValueError(f"packed prefilter must be (2J ≥ 4, H, W, 4), got {rgba.shape}")
        j, h, w = rgba.shape[0] // 2, rgba.shape[1], rgba.shape[2]
        ensure_gpu_context()
        texture = gpu.types.GPUTexture((w, h, 2 * j), format="RGBA32F", data=float_buffer(rgba))
        texture.filter_mode(True)
        texture.extend_mode("EXTEND")
        texture.extend_mode_x("REPEAT")
        return cls(texture, j, w, h)


@dataclass
class FilmTexture:
    """A film's reflectance against u = cos θ and its multiple-scattering factor, for the lamps
    (precompute.colour.film_colour.FilmTable).

    ``texture`` (:data:`FILM_SAMPLER`, RGBA32F): width U = u uniform 0…1 inclusive, height T =
    the table's thickness rows; spectral films: layers 0…2 = rows of the film's 3×3 reflectance,
    layer 3 = the multiple-scattering factor at view cosine u; per-channel films: layer 0 = the RGB
    reflectance, layer 1 = the factor; a film with a diffuse base then one more layer, the base's
    BRDF at view cosine u (``FilmTable.diffuse``, tf_film_diffuse). Interpolated in full float32
    like the table (tf_lamps.glsl).
    """

    texture: gpu.types.GPUTexture
    samples: int
    thickness_count: int
    spectral: bool
    #: The same texels as a :data:`FILM` uniform buffer when they fit: drawn from there on every
    #: device (docs/tuning.md#table-ubo-devices).
    ubo: gpu.types.GPUUniformBuf | None = None

    @staticmethod
    def layer_array(film) -> np.ndarray:
        """(layers, T, U, 4) float32: the reflectance rows, then the multiple-scattering factor,
        then the diffuse base's BRDF where the film has a base."""
        r = np.asarray(film.reflectance, dtype=np.float32)
        rows = [r[:, :, k, :] for k in range(3)] if r.ndim == 4 else [r]
        rows.append(np.asarray(film.multiscatter, dtype=np.float32))
        if film.diffuse is not None:
            rows.append(np.asarray(film.diffuse, dtype=np.float32))
        out = np.zeros((len(rows),) + r.shape[:2] + (4,), dtype=np.float32)
        for i, row in enumerate(rows):
            out[i, ..., :3] = row
        return out

    @classmethod
    def from_film(cls, film) -> FilmTexture:
        """Upload a film colour table; refuses non-finite values."""
        layers = cls.layer_array(film)
        if not np.all(np.isfinite(layers)):
            raise ValueError("the film table holds non-finite values")
        n_layers, t, u = layers.shape[:3]
        if u < 2:
            raise ValueError("the film table needs at least 2 samples in u")
        ensure_gpu_context()
        texture = gpu.types.GPUTexture((u, t), layers=n_layers, format="RGBA32F", data=float_buffer(layers))
        packed = texel_block(FILM, layers)
        ubo = gpu.types.GPUUniformBuf(float_buffer(packed)) if packed is not None else None
        return cls(texture, u, t, film.reflectance.ndim == 4, ubo)


@dataclass
class RadianceGridTexture:
    """A constant-thickness film's outgoing-radiance grid (precompute.shading.radiance_grid.build,
    precompute.shading.lobe_grid.build), or a varying film's film-free basis grid
    (lobe_grid.build_basis: policy.GRID_HATS hats side by side along the width, each W + 2 cells
    with a column of padding each side, and Ψ more layers holding each view node's hat range).

    ``texture`` (:data:`RADIANCE_GRID_SAMPLER`, RGBA16F: 4.5–9 MiB, policy.grid_shape): a 2-D
    array of W × H mirror-direction cells, equirect, top row first; layer j·Ψ + k = θo node j and
    view azimuth k. LINEAR, REPEAT in u, EXTEND in t: the shader interpolates the mirror direction
    by the filter and θo and ψ by hand (tf_radiance_grid.glsl).
    """

    texture: gpu.types.GPUTexture
    shape: tuple

    @classmethod
    def from_grid(cls, grid) -> RadianceGridTexture:
        """Upload a grid: its :class:`GridTexels` (made on the worker that built it), or a
        (T·Ψ, H, W, 3) grid, checked and padded here (:func:`grid_texels`)."""
        texels = grid_texels(grid)
        w, h, t, p = texels.shape
        ensure_gpu_context()
        texture = gpu.types.GPUTexture((w, h), layers=t * p, format="RGBA16F", data=float_buffer(texels.rgba))
        texture.filter_mode(True)
        texture.extend_mode("EXTEND")
        texture.extend_mode_x("REPEAT")
        return cls(texture, texels.shape)


@dataclass(frozen=True)
class GridTexels:
    """A radiance grid ready for :meth:`RadianceGridTexture.from_grid`: ``rgba`` (T·Ψ, H, W, 4)
    float32, finite, alpha 0; ``shape`` (W, H, T, Ψ)."""

    rgba: np.ndarray
    shape: tuple


def grid_texels(grid) -> GridTexels:
    """The texels of a (T·Ψ, H, W, 3) grid (:func:`precompute.shading.radiance_grid.texels`:
    checked and padded to RGBA, numpy only, so the worker that built the grid makes them and
    the main thread only uploads); a :class:`GridTexels` is returned as it is."""
    if isinstance(grid, GridTexels):
        return grid
    return GridTexels(*radiance_grid.texels(grid))


def lights_content(lights: Lights | None) -> np.ndarray | None:
    """:data:`LIGHTS` content (float32) of the first :data:`MAX_LIGHTS` lights, or None without
    any (the variant then has no light loop)."""
    if lights is None or lights.count == 0:
        return None
    packed = lights.pack()[: LIGHT_VEC4 * MAX_LIGHTS]
    return LIGHTS.pack(count=[packed.shape[0] // LIGHT_VEC4], light=packed)


def light_count(content) -> int:
    """The number of lights in :func:`lights_content`'s output (0 for None)."""
    return 0 if content is None else int(np.asarray(content).reshape(-1)[0])


class UniformCache:
    """Uniform buffers keyed by what they are made from, kept across frames.

    :meth:`get` returns the buffer made for an equal key before (no upload, no allocation), else
    fills one from ``make()`` (a float32 array): a buffer that no frame has used for
    ``keep_frames`` frames is updated in place, and only when there is none is a new one
    allocated. :meth:`next_frame` (called by :func:`.draw.prepare_draw`) ages the entries. So a
    frame in which nothing moved allocates and uploads nothing, and a moving view or object
    recycles old buffers instead of allocating one per frame. A buffer is updated only
    ``keep_frames`` frames after its last use, when those draws have long been submitted.

    ``stats``: ``allocations`` (new GPUUniformBuf), ``uploads`` (updates of a recycled one),
    ``hits`` (reused unchanged).
    """

    def __init__(self, keep_frames: int = 4, max_spare: int = 256):
        self.keep_frames = int(keep_frames)
        self.max_spare = int(max_spare)
        self.frame = 0
        self._entries: dict = {}  # key → [ubo, nbytes, last frame used]
        self._spare: dict[int, list] = {}  # nbytes → buffers free for reuse
        self.stats = {"allocations": 0, "uploads": 0, "hits": 0}

    def next_frame(self) -> None:
        """Advance the frame counter and recycle buffers unused for *keep_frames* frames."""
        self.frame += 1
        oldest = self.frame - self.keep_frames
        stale = [key for key, entry in self._entries.items() if entry[2] < oldest]
        for key in stale:
            ubo, nbytes, _last = self._entries.pop(key)
            spare = self._spare.setdefault(nbytes, [])
            if len(spare) < self.max_spare:
                spare.append(ubo)

    def get(self, key, make) -> gpu.types.GPUUniformBuf:
        """The uniform buffer for *key*, created with *make* when missing."""
        entry = self._entries.get(key)
        if entry is not None:
            entry[2] = self.frame
            self.stats["hits"] += 1
            return entry[0]
        data = float_buffer(make())
        nbytes = 4 * len(data)
        spare = self._spare.get(nbytes)
        if spare:
            ubo = spare.pop()
            ubo.update(data)
            self.stats["uploads"] += 1
        else:
            ubo = gpu.types.GPUUniformBuf(data)
            self.stats["allocations"] += 1
        self._entries[key] = [ubo, nbytes, self.frame]
        return ubo

    def __len__(self):
        return len(self._entries)

    def clear(self) -> None:
        """Release every buffer, in use or spare."""
        self._entries.clear()
        self._spare.clear()


@dataclass
class DisplayLUTTexture:
    """The display LUT (precompute/colour/display_lut.py) as an RGBA32F texture of N · N × (N + 1)
    texels (the last row: the input matrix), read with texelFetch (:data:`DISPLAY_LUT_SAMPLER`)."""

    texture: gpu.types.GPUTexture
    size: int

    @classmethod
    def from_table(cls, table, matrix=None) -> DisplayLUTTexture:
        """Upload an (N, N, N, 3) LUT indexed [b, g, r] and its input matrix (None: identity)."""
        rgba = display_lut.texture_layout(table, matrix)
        n = rgba.shape[0] - 1
        texture = gpu.types.GPUTexture((n * n, n + 1), format="RGBA32F", data=float_buffer(rgba))
        return cls(texture, n)


@dataclass
class BehindTexture:
    """The scene drawn without the films, which solid glass refracts (``TF_REFRACT``,
    precompute/shading/glass/refract.py): an RGBA32F texture (:data:`BEHIND_SAMPLER`; .rgb its
    scene-linear colour, .a its depth, the distance along the camera axis,
    policy.REFRACT_FAR where nothing was drawn; read with texelFetch) and the :data:`BEHIND`
    buffer placing it in the drawn window; the glass buffers ``front`` and ``back`` (the drawn
    window's solid glass faces, :mod:`.glass_buffers`; 1 × 1 empty ones without), their faces'
    geometric normals ``geom`` and ``ids`` (a glass item's name → its id there)."""

    texture: gpu.types.GPUTexture
    ubo: gpu.types.GPUUniformBuf
    width: int
    height: int
    front: gpu.types.GPUTexture | None = None
    back: gpu.types.GPUTexture | None = None
    #: A glass draw item (its ``id()``) → its id in the glass buffers and ``film``.
    ids: dict = field(default_factory=dict)
    #: Cycles' back-face film per glass id (rows), u uniform 0…1 (columns), .a = 1 where given.
    film: gpu.types.GPUTexture | None = None
    #: The glass buffers' geometric normals (:mod:`.glass_buffers`: .xy front, .zw back).
    geom: gpu.types.GPUTexture | None = None
    #: The scene around the glass seen from one point (:meth:`with_probe`; tf_probe.glsl), or None.
    probe: gpu.types.GPUTexture | None = None
    #: The window → uv map the buffer was packed with (:meth:`screen`).
    window: tuple = (1.0, 1.0, 0.0, 0.0)

    def probe_texture(self) -> gpu.types.GPUTexture:
        """The probe's texture, a 2 × 1 empty one (no distance: the World) where none was given."""
        if self.probe is None:
            empty = float_buffer(np.zeros((1, 2, 4)))
            self.probe = gpu.types.GPUTexture((2, 1), format="RGBA32F", data=empty)
        return self.probe

    def with_probe(self, probe, centre) -> BehindTexture:
        """This texture with the scene probe ``probe`` (rows, 2 rows, 4: colour and distance from
        ``centre``, 0 where the World; shading.glass.probe.from_faces) uploaded, row 0 its top."""
        probe = np.asarray(probe, dtype=np.float64)
        if probe.ndim != 3 or probe.shape[2] != 4 or probe.shape[1] != 2 * probe.shape[0]:
            raise ValueError(f"a scene probe is an equirect panorama (rows, 2 rows, 4), got {probe.shape}")
        texels = np.nan_to_num(probe, nan=0.0, posinf=0.0, neginf=0.0)
        size = (probe.shape[1], probe.shape[0])
        self.probe = gpu.types.GPUTexture(size, format="RGBA32F", data=float_buffer(texels))
        centre = [float(v) for v in np.asarray(centre, dtype=np.float64).reshape(3)]
        content = BEHIND.pack(screen=self.window, size=(self.width, self.height, 0, 0), probe=(*centre, 1.0))
        self.ubo = gpu.types.GPUUniformBuf(float_buffer(content))
        return self

    def glass_textures(self) -> tuple:
        """(front, back, film, geom): the glass buffers, back-face films and the buffers'
        geometric normals, empty ones (one texel a layer; the film 2 × 1) where none were drawn."""
        empty = float_buffer(np.zeros((1, 2, 4)))
        if self.front is None or self.back is None:
            layers = policy.GLASS_LAYERS  # 2D arrays (.glass_buffers)
            none = float_buffer(np.zeros((layers, 1, 1, 4)))
            self.front, self.back, self.geom = (
                gpu.types.GPUTexture((1, 1), layers=layers, format="RGBA32F", data=none) for _ in range(3)
            )
        if self.geom is None:
            raise ValueError("the glass buffers were given without their geometric normals (geom)")
        if self.film is None:
            self.film = gpu.types.GPUTexture((2, 1), format="RGBA32F", data=empty)
        return self.front, self.back, self.film, self.geom

    @staticmethod
    def screen(width: int, height: int, pad: int, margin: int = 0) -> tuple[float, ...]:
        """The window → uv map (sx, sy, ox, oy) of a frame of ``width`` × ``height`` pixels drawn
        widened by ``pad`` pixels on each side (the headless frame's filter margin; its
        supersampling does not change the map), for an image of that frame widened by ``margin``
        pixels on each side (the background pass's overscan)."""
        iw, ih = width + 2.0 * margin, height + 2.0 * margin
        sx, sy = (width + 2.0 * pad) / iw, (height + 2.0 * pad) / ih
        return (sx, sy, (margin - pad) / iw, (margin - pad) / ih)

    @classmethod
    def from_image(cls, rgb, depth, screen=(1.0, 1.0, 0.0, 0.0)) -> BehindTexture:
        """Upload ``rgb`` (H, W, 3+, top row first) and ``depth`` (H, W: distance along the camera
        axis, inf where empty) with the window → uv map ``screen`` (:meth:`screen`)."""
        rgb = np.asarray(rgb, dtype=np.float64)
        depth = np.asarray(depth, dtype=np.float64)
        if rgb.ndim != 3 or rgb.shape[2] < 3 or depth.shape != rgb.shape[:2]:
            raise ValueError(
                f"the scene behind needs colour (H, W, 3) and depth (H, W), got {rgb.shape} and {depth.shape}"
            )
        height, width = depth.shape
        far = np.where(np.isfinite(depth), np.minimum(depth, policy.REFRACT_FAR), policy.REFRACT_FAR)
        texels = np.concatenate([np.nan_to_num(rgb[..., :3]), far[..., None]], axis=-1)[::-1]
        texture = gpu.types.GPUTexture((width, height), format="RGBA32F", data=float_buffer(texels))
        content = BEHIND.pack(screen=screen, size=(width, height, 0, 0))
        ubo = gpu.types.GPUUniformBuf(float_buffer(content))
        return cls(texture, ubo, width, height, window=tuple(float(v) for v in screen))
