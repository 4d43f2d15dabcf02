"""What the shaders read: binding slots and uniform-buffer layouts, each written once.

Every uniform buffer is described once, as a :class:`Block` of vec4 members (std140 with vec4s
only, so a member's offset is the sum of the members before it): :data:`LIGHTING`, :data:`VIEW`,
:data:`OBJECT`, :data:`TABLE`, :data:`FILM`, :data:`LIGHTS` and :data:`BEHIND`. Its binding
slot, its GLSL struct (:data:`TYPEDEFS`, with each member's description as a comment) and its
packing (:meth:`Block.pack`) all come from that description, and its size is checked against
UBO_LIMIT_BYTES (16 KiB, the minimum every backend guarantees) when this module loads. The
samplers are :class:`Sampler` records; each texture's layout is in the docstring of the class
that fills it (:mod:`.resources`: ``TableTexture``, ``FilmTexture``, ``PrefilterTexture``,
``EnvironmentTexture``). The GLSL chunks name the members and point here. No push constants
are used (Vulkan keeps only 128 bytes of them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...precompute.materials.material import MAX_SH_ORDER
from ...precompute.shading import policy
from ...precompute.shading.codegen import RX_PADDED
from ...precompute.shading.lights import LIGHT_VEC4
from ...precompute.shading.variant import UBO_LIMIT_BYTES, UBO_TEXELS

#: Highest SH order the shaders support (the lighting buffer always has room for it).
MAX_L = MAX_SH_ORDER
#: World SH coefficients in the lighting buffer: (MAX_L + 1)².
SH_SLOTS = (MAX_L + 1) ** 2
#: The World's lamps the lighting buffer holds (precompute/world/lamps.py): a count, then direction and
#: power of each.
MAX_LAMPS = policy.MAX_LAMPS
LAMP_VEC4 = 1 + 2 * MAX_LAMPS


# ----------------------------------------------------------------------------------------------
# Layouts
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Member:
    """``count`` vec4s of a uniform block (None: one vec4, not an array) and what they hold.

    ``doc`` is the layout's one description: it is written into the GLSL struct as a comment, so
    it is plain ASCII.
    """

    name: str
    count: int | None
    doc: str

    @property
    def vec4s(self) -> int:
        """Number of vec4 slots the member takes (its array length, or 1)."""
        return 1 if self.count is None else int(self.count)

    def glsl(self) -> str:
        """The member's line in the GLSL struct, with its description as a comment."""
        array = "" if self.count is None else f"[{self.count}]"
        return f"  vec4 {self.name}{array}; /* {self.doc} */"


@dataclass(frozen=True)
class Block:
    """A std140 uniform buffer of vec4 members: the GLSL type ``struct``, the resource ``name``
    the shaders read it as, its binding ``slot`` and its members in order."""

    struct: str
    name: str
    slot: int
    members: tuple[Member, ...]

    def __post_init__(self):
        if self.nbytes > UBO_LIMIT_BYTES:
            raise ValueError(
                f"{self.struct} is {self.nbytes} bytes, over the {UBO_LIMIT_BYTES} every GPU has"
            )
        for m in self.members:
            if not m.doc.isascii() or "*/" in m.doc:
                raise ValueError(f"{self.struct}.{m.name}: the description goes into GLSL (ASCII, no */)")

    @property
    def vec4s(self) -> int:
        """Number of vec4 slots in the whole block."""
        return sum(m.vec4s for m in self.members)

    @property
    def nbytes(self) -> int:
        """Size of the block in bytes (16 per vec4, std140)."""
        return 16 * self.vec4s

    def offset(self, member: str) -> int:
        """The vec4 offset of ``member``."""
        at = 0
        for m in self.members:
            if m.name == member:
                return at
            at += m.vec4s
        raise KeyError(f"{self.struct} has no member {member!r}")

    def typedef(self) -> str:
        """The block's GLSL struct declaration, generated from the members."""
        return "\n".join([f"struct {self.struct} {{", *(m.glsl() for m in self.members), "};"])

    def pack(self, **values) -> np.ndarray:
        """The buffer's content, (vec4s, 4) float32: each member from ``values`` (anything of at
        most its vec4s × 4 floats, read row-major), zero where a member or its tail is not given."""
        unknown = set(values) - {m.name for m in self.members}
        if unknown:
            raise KeyError(f"{self.struct} has no member(s) {sorted(unknown)}")
        out = np.zeros((self.vec4s, 4), dtype=np.float32)
        flat = out.reshape(-1)
        for m in self.members:
            if m.name not in values:
                continue
            data = np.asarray(values[m.name], dtype=np.float64).reshape(-1)
            if data.size > 4 * m.vec4s:
                raise ValueError(f"{self.struct}.{m.name} holds {4 * m.vec4s} floats, got {data.size}")
            start = 4 * self.offset(m.name)
            flat[start : start + data.size] = data
        return out


@dataclass(frozen=True)
class Sampler:
    """A texture binding: slot, ``GPUShaderCreateInfo.sampler`` type and resource name."""

    slot: int
    type: str
    name: str


#: The World's radiance SH (windowed for one material), its lamps and the SH rotation constants
#: (:class:`Lighting`). One set of X(+90°) blocks: reading X(−90°) as their transpose fits l ≤ 12
#: in 16 KiB (both sets would need 26 KiB).
LIGHTING = Block(
    "TFLighting",
    "tf_lighting",
    0,
    (
        Member(
            "sh",
            SH_SLOTS,
            "World radiance SH, windowed: coefficient i = l(l+1)+m in .rgb (w = 0), zero beyond the data",
        ),
        Member(
            "lamps",
            LAMP_VEC4,
            "the World's lamps: [0].x = count K <= TF_MAX_LAMPS, [1+2k].xyz = direction of lamp k"
            " (unit, towards it), [2+2k].rgb = its power (sum of L d omega); all 0 without lamps",
        ),
        Member(
            "rx",
            RX_PADDED // 4,
            f"Rx(+90) band blocks, l = 0..{MAX_L}, row-major, band l at scalar offset l(2l-1)(2l+1)/3"
            " (codegen.x_rotation_scalars); Rx(-90) = their transpose",
        ),
        Member(
            "world",
            3,
            "the World's turn and strength for the prefilter and radiance-grid lookups: rows of Q"
            " in .xyz (image direction = Q world direction), [0].w = their scale; identity and 1 by"
            " default",
        ),
    ),
)
_VIEW_MEMBERS = (
    Member("view_proj", 4, "view-projection matrix, columns"),
    Member("inv_view_proj", 4, "its inverse, columns"),
    Member("camera", None, "camera position, w = 1 for an orthographic view"),
    Member("view_dir", None, "unit direction towards the viewer"),
    Member("params", None, "x: 2^exposure"),
)
#: The view (:func:`.draw.view_uniforms`).
VIEW = Block("TFView", "tf_view", 1, _VIEW_MEMBERS)
#: One drawn object (:func:`.draw.object_uniforms`).
OBJECT = Block(
    "TFObject",
    "tf_object",
    2,
    (
        Member("model", 4, "model matrix, columns"),
        Member("normal", 4, "normal matrix (inverse transpose of the model's 3x3), columns"),
        Member("material", None, "x: roughness, y: SH weight of the split-sum blend, z, w: wall mode, eta"),
        Member(
            "glass",
            None,
            "x: solid glass's id in the glass buffers (TF_REFRACT), -1 where none; "
            "yzw: the wall's transmission tint (Principled Base Color), 1 where none",
        ),
        Member(
            "fit",
            None,
            "a thin wall's thickness parameter as fit.xyz . p + fit.w over world positions p, the "
            "mesh's least-squares fit (shading.transmit.world_fit); 0 for a constant thickness",
        ),
        Member(
            "inside",
            None,
            "x: 1 where a closed thin wall draws its reflections inside (shading.transmit.Inside.drawn)",
        ),
        Member(
            "noise",
            None,
            "a noise thickness per pixel (TF_THICKNESS_NOISE): x scale, y seed (tf_noise.glsl) or W "
            "(a Noise Texture, TF_THICKNESS_PERLIN, tf_perlin.glsl), z 1 where its Color Ramp "
            "interpolates (TF_THICKNESS_RAMP), w its Distortion",
        ),
        Member("noise_fbm", None, "TF_THICKNESS_PERLIN: detail, roughness, lacunarity, dimensions (3, 4)"),
        Member("noise_map", None, "TF_THICKNESS_PERLIN: gain, bias, low, high (Fac to the parameter)"),
        Member(
            "noise_space_x",
            None,
            "TF_THICKNESS_PERLIN: xyz row x of the coordinates' matrix from object space",
        ),
        Member("noise_space_y", None, "TF_THICKNESS_PERLIN: xyz its row y"),
        Member("noise_space_z", None, "TF_THICKNESS_PERLIN: xyz its row z"),
        Member("noise_offset", None, "TF_THICKNESS_PERLIN: xyz the coordinates' offset"),
    ),
)
#: A small table instead of its texture (``TF_TABLE_UBO``, :attr:`TableTexture.ubo`).
TABLE = Block(
    "TFTable",
    "tf_table_data",
    3,
    (
        Member("size", None, "view angles A, thickness rows T, layers"),
        Member(
            "texel",
            UBO_TEXELS,
            "texel (row t, column a, layer j) at (t * A + a) * layers + j, .rgb as in the texture tf_table",
        ),
    ),
)
#: The lamps' small film table instead of its texture (``TF_FILM_UBO``, :attr:`FilmTexture.ubo`).
FILM = Block(
    "TFFilm",
    "tf_film_data",
    4,
    (
        Member("size", None, "u samples U, thickness rows T, layers"),
        Member(
            "texel",
            UBO_TEXELS,
            "texel (row t, column u, layer j) at (t * U + u) * layers + j, .rgb as in the texture tf_film",
        ),
    ),
)
#: Blender's light objects of the frame (``TF_LIGHTS``, :func:`lights_content`).
MAX_LIGHTS = policy.MAX_LIGHTS
LIGHTS = Block(
    "TFLights",
    "tf_lights",
    5,
    (
        Member("count", None, "x: K <= TF_MAX_LIGHTS"),
        Member(
            "light",
            LIGHT_VEC4 * MAX_LIGHTS,
            "light k at [5k..5k+4]: position, kind; direction, radius; energy, cos_half_spot or"
            " tan_half_spread; axis_u, spot_smooth or normalize_spread; axis_v, ellipse"
            " (shading.lights.Lights.pack)",
        ),
    ),
)
#: Where the scene-behind texture lies in the drawn window (``TF_REFRACT``, :class:`BehindTexture`).
BEHIND = Block(
    "TFBehind",
    "tf_behind_view",
    6,
    (
        Member("screen", None, "xy: scale, zw: offset from the drawn window's [0, 1] to the texture's uv"),
        Member("size", None, "xy: the texture's width and height in texels"),
        Member("probe", None, "xyz: the scene probe's point (world), w: 1 if rendered (tf_probe.glsl)"),
    ),
)
#: The GLSL structs of every block, declared by every shader.
TYPEDEFS = "\n" + "\n".join(b.typedef() for b in (LIGHTING, VIEW, OBJECT, TABLE, FILM, LIGHTS, BEHIND)) + "\n"
#: vec4s of the lighting buffer.
LIGHTING_VEC4 = LIGHTING.vec4s
assert TABLE.nbytes == FILM.nbytes == UBO_LIMIT_BYTES  # the tables use all of it (UBO_TEXELS)

TABLE_SAMPLER = Sampler(0, "FLOAT_2D_ARRAY", "tf_table")
PREFILTERED_SAMPLER = Sampler(3, "FLOAT_3D", "tf_prefiltered")
FILM_SAMPLER = Sampler(4, "FLOAT_2D_ARRAY", "tf_film")
#: A film's thickness parameter in [0, 1] over the mesh's UVs (``TF_THICKNESS_MAP``, R32F, bilinear,
#: edges extended; :mod:`..thickness.maps`), bound per draw.
THICKNESS_MAP_SAMPLER = Sampler(5, "FLOAT_2D", "tf_thickness_map")
#: A Color Ramp's table (``TF_THICKNESS_RAMP``, 257 × 1 R32F, read with texelFetch;
#: :func:`.mesh.ramp_texture`), bound per draw; a ramp variant has no map, so it takes the map's slot.
THICKNESS_RAMP_SAMPLER = Sampler(5, "FLOAT_2D", "tf_thickness_ramp")
RADIANCE_GRID_SAMPLER = Sampler(6, "FLOAT_2D_ARRAY", "tf_radiance_grid")
#: The background shader's only texture.
ENVIRONMENT_SAMPLER = Sampler(0, "FLOAT_2D", "tf_environment")
#: The display LUT (tf_display.glsl, :class:`DisplayLUTTexture`) of ``TF_DISPLAY_LUT`` variants.
DISPLAY_LUT_SAMPLER = Sampler(7, "FLOAT_2D", "tf_display_lut")
#: The scene drawn without the films (:class:`BehindTexture`) of ``TF_REFRACT`` variants.
BEHIND_SAMPLER = Sampler(8, "FLOAT_2D", "tf_behind")
#: Solid glass's nearest front and back faces per pixel (:class:`.resources.BehindTexture`,
#: ``TF_REFRACT``).
GLASS_FRONT_SAMPLER = Sampler(9, "FLOAT_2D_ARRAY", "tf_glass_front")
GLASS_BACK_SAMPLER = Sampler(10, "FLOAT_2D_ARRAY", "tf_glass_back")
#: Cycles' film seen from inside each solid glass (row = its id; tf_glass_exit.glsl tf_glass_back_r).
GLASS_FILM_SAMPLER = Sampler(11, "FLOAT_2D", "tf_glass_film")
#: The geometric normals of those faces (.xy the front face's, .zw the back face's, octahedral;
#: tf_glass_exit.glsl tf_glass_outside), for Cycles' rules at smooth-shaded faces.
GLASS_GEOM_SAMPLER = Sampler(12, "FLOAT_2D_ARRAY", "tf_glass_geom")
#: The scene around solid glass seen from one point (:class:`BehindTexture` ``probe``, tf_probe.glsl).
PROBE_SAMPLER = Sampler(13, "FLOAT_2D", "tf_probe")
#: The glass buffers' shader's only texture (``TF_GLASS_FURTHER``, :mod:`.glass_buffers`): the
#: layer before, whose faces a further layer's lie behind.
GLASS_PEEL_SAMPLER = Sampler(0, "FLOAT_2D", "tf_glass_peel")
