"""Solid glass in the shader's numpy mirror: the scene behind refracted through it (:mod:`.refract`,
glsl/tf_refract.glsl), its exit through its real mesh (:mod:`.glass_exit`,
glsl/tf_glass_exit.glsl) and the World's lamps in a rough path's tails (:mod:`.tails`,
glsl/tf_glass_tails.glsl)."""
