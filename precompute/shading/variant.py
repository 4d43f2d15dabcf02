"""The shader variant: which GLSL a draw compiles, and the pure decisions that pick it.

A :class:`Variant` names every switch of the shading library (each a ``#define``); the add-on
compiles one shader per variant (addon/gpu/shaders.py ``ShaderCache``) and the effect plan
(precompute/effects/) costs the same variant (codegen.operation_counts).
:func:`choose_variant` turns the facts of one draw item (its table, mesh, World and film) into
it, for the draw and for the plan alike.
"""

from __future__ import annotations

from typing import NamedTuple

from ..materials.perlin import distortion_offsets
from . import policy

#: Minimum uniform-buffer size every backend guarantees (GL_MAX_UNIFORM_BLOCK_SIZE ≥ 16 KiB).
UBO_LIMIT_BYTES = 16384
#: RGBA32F texels of a table (or the lamps' film table) that fit one uniform buffer next to its
#: vec4 size header: only then can it be drawn from the buffer (``TF_TABLE_UBO``, ``TF_FILM_UBO``).
UBO_TEXELS = UBO_LIMIT_BYTES // 16 - 1


#: A transparent film's passes (``TF_TRANSMIT``): first multiply what is behind by T, then add R·L.
TRANSMIT_MULTIPLY = 1
TRANSMIT_ADD = 2
TRANSMIT_PASSES = (TRANSMIT_MULTIPLY, TRANSMIT_ADD)
#: ``Variant.thickness_noise``: the *Noise* source's value noise, Blender's Noise Texture, and a
#: Noise Texture read through a Color Ramp's table (``TF_THICKNESS_RAMP``).
NOISE_VALUE, NOISE_BLENDER, NOISE_RAMP = 1, 2, 3
#: The noises that are a Noise Texture (tf_perlin.glsl), which may read ``orco``.
_TEXTURES = (NOISE_BLENDER, NOISE_RAMP)


def _distortion_offsets() -> list[tuple[str, str]]:
    """A distorted Noise Texture's fixed offsets (materials.perlin.distortion_offsets) as GLSL
    matrices, one column per axis: ``TF_NOISE_DISTORT3`` (mat3), ``TF_NOISE_DISTORT4`` (mat4)."""
    out = []
    for n in (3, 4):
        values = ", ".join(repr(float(x)) for x in distortion_offsets(n).ravel())
        out.append((f"TF_NOISE_DISTORT{n}", f"mat{n}({values})"))
    return out


def fits_uniform_buffer(layers: int, rows: int, columns: int) -> bool:
    """Whether a table of ``layers`` × ``rows`` × ``columns`` RGBA texels fits :data:`UBO_TEXELS`."""
    return int(layers) * int(rows) * int(columns) <= UBO_TEXELS


class Variant(NamedTuple):
    """A compiled shader variant (a NamedTuple: hashable, the shader cache's key)."""

    #: Highest SH band of the table (``TF_L_MAX``).
    l_max: int
    #: A 3×3 colour matrix per coefficient (``TF_SPECTRAL``), else RGB factors.
    spectral: bool
    #: Thickness from the per-vertex attribute over the table's rows (``TF_VARY_THICKNESS``).
    vary_thickness: bool
    #: Output display-encoded: exposure, clamp, sRGB (``TF_DISPLAY_SRGB``).
    display: bool
    #: Split sum blended with SH by roughness (``TF_SPLIT_SUM``, tf_split_sum.glsl).
    split_sum: bool = False
    #: The table read from the ``TFTable`` uniform buffer instead of its texture (``TF_TABLE_UBO``).
    table_ubo: bool = False
    #: Split sum alone (``sh_weight`` = 0, glossy films): the SH half is compiled out.
    split_only: bool = False
    #: The World's lamps shaded per light direction (tf_lamps.glsl, the film texture).
    lamps: bool = False
    #: The lamps' film table read from the ``TFFilm`` uniform buffer (small tables).
    film_ubo: bool = False
    #: Blender's light objects shaded per sample (``TF_LIGHTS``, tf_lights.glsl, the film texture).
    lights: bool = False
    #: With ``display``: the scene's view transform through the baked display LUT
    #: (``TF_DISPLAY_LUT``, tf_display.glsl) instead of the Standard sRGB encoding.
    display_lut: bool = False
    #: A transparent film's blend pass (``TF_TRANSMIT``, tf_transmit.glsl, the film texture):
    #: 0 opaque, :data:`TRANSMIT_MULTIPLY` (writes T) or :data:`TRANSMIT_ADD` (writes R·L).
    transmit: int = 0
    #: The SH half read from the outgoing-radiance grid (``TF_RADIANCE_GRID``,
    #: tf_radiance_grid.glsl; policy.uses_grid): no SH code is compiled.
    grid: bool = False
    #: Solid glass sees the scene behind along its exit ray (``TF_REFRACT``, tf_refract.glsl, the
    #: scene-behind texture): a transparent film's passes over a frame drawn without the films.
    refract: bool = False
    #: With ``vary_thickness``: the thickness parameter read per pixel from the batch's thickness
    #: map at its UVs (``TF_THICKNESS_MAP``; addon/thickness/maps.py), not from the corners.
    thickness_map: bool = False
    #: With ``vary_thickness``: a noise source computed per pixel from the object-space position
    #: (``TF_THICKNESS_NOISE``), not from the corners: :data:`NOISE_VALUE` the Noise source
    #: (tf_noise.glsl: materials.noise.value_noise), :data:`NOISE_BLENDER` the Blender Noise
    #: source (``TF_THICKNESS_PERLIN`` too, tf_perlin.glsl: materials.perlin.blender_noise),
    #: :data:`NOISE_RAMP` a linked Noise Texture through a Color Ramp (``TF_THICKNESS_RAMP`` too:
    #: materials.ramp.lookup of the ramp's table, a texture); 0 none (True and False read as 1
    #: and 0).
    thickness_noise: int = 0
    #: With a Noise Texture per pixel: it reads where the vertices were before a deformation
    #: (Generated coordinates after Deform modifiers or shape keys: the batch's ``orco``
    #: attribute, ``TF_NOISE_ORCO``), not their positions.
    noise_orco: bool = False

    @property
    def film(self) -> bool:
        """The film's reflectance table is read (for the World's lamps, the light objects, a
        transparent film's transmittance, or a varying film's basis grid)."""
        return bool(self.lamps or self.lights or self.transmit or (self.grid and self.vary_thickness))

    @property
    def moment(self) -> bool:
        """The split sum reads its albedo at the dominant-direction angle (``TF_MOMENT``,
        policy.uses_moment)."""
        return bool(self.split_sum) and policy.uses_moment(self.l_max, self.split_only)

    def normalised(self) -> Variant:
        """The same variant with plain ``int``/``bool`` fields and the flags that need another
        cleared (split-only without the split sum, a film uniform buffer without lamps or lights)."""
        return Variant(
            int(self.l_max),
            bool(self.spectral),
            bool(self.vary_thickness),
            bool(self.display),
            bool(self.split_sum),
            bool(self.table_ubo),
            bool(self.split_sum and self.split_only),
            bool(self.lamps),
            bool(
                (self.lamps or self.lights or self.transmit or (self.grid and self.vary_thickness))
                and self.film_ubo
            ),
            bool(self.lights),
            bool(self.display and self.display_lut),
            int(self.transmit) if int(self.transmit) in TRANSMIT_PASSES else 0,
            bool(self.grid and not self.split_only),
            bool(self.refract and int(self.transmit) in TRANSMIT_PASSES),
            bool(self.vary_thickness and self.thickness_map),
            int(self.thickness_noise) if self.vary_thickness else 0,
            bool(self.noise_orco and self.vary_thickness and int(self.thickness_noise) in _TEXTURES),
        )

    def _thickness_switches(self) -> list[tuple[str, str]]:
        """A varying thickness's ``#define``s: over the rows, and read per pixel (map or noise)."""
        if not self.vary_thickness:
            return []
        out = [("TF_VARY_THICKNESS", "1")]
        if self.thickness_map:
            out.append(("TF_THICKNESS_MAP", "1"))
        if self.thickness_noise:
            out.append(("TF_THICKNESS_NOISE", "1"))
        if int(self.thickness_noise) in (NOISE_BLENDER, NOISE_RAMP):
            out.append(("TF_THICKNESS_PERLIN", "1"))
            out += _distortion_offsets()
        if int(self.thickness_noise) == NOISE_RAMP:
            out.append(("TF_THICKNESS_RAMP", "1"))
        if self.noise_orco and int(self.thickness_noise) in _TEXTURES:
            out.append(("TF_NOISE_ORCO", "1"))
        return out

    def _display_switches(self) -> list[tuple[str, str]]:
        """The display encoding's ``#define``s: Standard sRGB, and the scene's view LUT."""
        if not self.display:
            return []
        return [("TF_DISPLAY_SRGB", "1")] + ([("TF_DISPLAY_LUT", "1")] if self.display_lut else [])

    def _transmit_switches(self) -> list[tuple[str, str]]:
        """A transparent film's ``#define``s: its blend pass, and solid glass's refraction."""
        if not self.transmit:
            return []
        return [("TF_TRANSMIT", str(int(self.transmit)))] + ([("TF_REFRACT", "1")] if self.refract else [])

    def switches(self) -> tuple[tuple[str, str], ...]:
        """The variant's own ``#define``s (name, value), in the order the shader declares them."""
        out = [("TF_L_MAX", str(int(self.l_max)))]
        if self.spectral:
            out.append(("TF_SPECTRAL", "1"))
        out += self._thickness_switches()
        out += self._display_switches()
        if self.split_sum:
            out.append(("TF_SPLIT_SUM", "1"))
            if self.split_only:
                out.append(("TF_SPLIT_ONLY", "1"))
            if self.moment:
                out.append(("TF_MOMENT", "1"))
        if self.lamps:
            out.append(("TF_LAMPS", "1"))
        if self.lights:
            out.append(("TF_LIGHTS", "1"))
        out += self._transmit_switches()
        if self.film and self.film_ubo:
            out.append(("TF_FILM_UBO", "1"))
        if self.table_ubo:
            out.append(("TF_TABLE_UBO", "1"))
        if self.grid:
            out.append(("TF_RADIANCE_GRID", "1"))
        return tuple(out)

    def defines(self) -> tuple[tuple[str, str], ...]:
        """Every ``#define`` the shading library needs: :meth:`switches`, then the shading rules
        (policy.glsl_defines)."""
        return self.switches() + policy.glsl_defines()


def choose_variant(
    *,
    l_max: int,
    spectral: bool,
    thickness_rows: int,
    has_thickness: bool,
    display: bool,
    prefiltered: bool,
    sh_weight: float,
    lamp_count: int = 0,
    film: bool = False,
    film_ubo: bool = False,
    table_ubo: bool = False,
    light_count: int = 0,
    display_lut: bool = False,
    transmit: int = 0,
    grid: bool = False,
    refract: bool = False,
    thickness_map: bool = False,
    thickness_noise: int = 0,
    noise_orco: bool = False,
) -> Variant:
    """The variant that draws one item, from its facts.

    - ``l_max``, ``spectral``, ``thickness_rows``: the baked table's;
    - ``has_thickness``: the mesh carries the thickness attribute (vary only with > 1 row);
    - ``prefiltered``: a prefiltered World is there; the split sum runs where it is and
      ``sh_weight`` (policy.sh_weight of the roughness) < 1, alone where the weight is 0 (a
      run-time branch on the weight did not save the SH half on llvmpipe: split only cost as
      much as split + SH);
    - ``lamp_count``, ``film``: the World's lamps and the material's film table; the lamp loop
      runs with both; ``film_ubo``: the film table is in a uniform buffer;
    - ``table_ubo``: the table is drawn from its uniform buffer (policy.TABLE_UBO_DEVICES and
      :func:`fits_uniform_buffer`);
    - ``light_count``: Blender's light objects in the frame; their loop runs with the film table;
    - ``display_lut``: a display LUT is bound (the scene's view transform, with ``display``).
    - ``transmit``: the blend pass of a transparent film (:data:`TRANSMIT_PASSES`, 0 opaque); it
      reads the film table, which the item must then carry.
    - ``grid``: the item has an outgoing-radiance grid; its SH half is read from it where
      policy.uses_grid says so (constant thickness, l_max ≥ GRID_MIN_L, an SH half drawn).
    - ``refract``: solid glass over a scene-behind texture (the headless frame's background pass):
      its passes march the exit ray over it (shading/glass/refract.py).
    - ``thickness_map``: the batch carries a thickness map and UVs (with a varying thickness);
      ``thickness_noise``: its thickness is a noise source computed per pixel (:data:`NOISE_VALUE`,
      :data:`NOISE_BLENDER`, :data:`NOISE_RAMP`; 0 none); ``noise_orco``: a Noise Texture's
      coordinates are the batch's positions before a deformation.
    """
    split = bool(prefiltered) and float(sh_weight) < 1.0
    lamps = bool(film) and int(lamp_count) > 0
    lights = bool(film) and int(light_count) > 0
    vary = bool(has_thickness) and int(thickness_rows) > 1
    weight = float(sh_weight) if split else 1.0
    # a varying film's grid is its film-free basis, read with the film table
    grid = bool(grid) and policy.uses_grid(l_max, vary, weight) and (bool(film) or not vary)
    return Variant(
        l_max=int(l_max),
        spectral=bool(spectral),
        vary_thickness=vary,
        display=bool(display),
        split_sum=split,
        table_ubo=bool(table_ubo),
        split_only=split and float(sh_weight) <= 0.0,
        lamps=lamps,
        film_ubo=(lamps or lights or bool(transmit) or (grid and vary)) and bool(film_ubo),
        lights=lights,
        display_lut=bool(display) and bool(display_lut),
        transmit=int(transmit) if bool(film) else 0,
        grid=grid,
        refract=bool(refract) and bool(film) and int(transmit) in TRANSMIT_PASSES,
        thickness_map=vary and bool(thickness_map),
        thickness_noise=int(thickness_noise) if vary else 0,
        noise_orco=vary and bool(noise_orco) and int(thickness_noise) in _TEXTURES,
    )


def stand_in(variant: Variant) -> Variant:
    """The variant drawn in place of ``variant`` while that one is not compiled yet: the same
    switches at order ≤ policy.STAND_IN_L and without the grid (its SH sum truncated there)."""
    v = variant.normalised()
    return v._replace(l_max=min(v.l_max, policy.STAND_IN_L), grid=False).normalised()
