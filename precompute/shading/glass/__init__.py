"""Solid glass in the shader's numpy mirror: the scene behind refracted through it (:mod:`.refract`,
glsl/tf_refract.glsl) and its exit through its real mesh (:mod:`.glass_exit`,
glsl/tf_glass_exit.glsl)."""
