"""The seed's real-time water shaders: GLSL sources and their Dr.Jit ports.

This layer takes plain inputs (textures, camera, constants) and knows nothing of
experiments, Mitsuba scenes or solvers.
"""
from ._inputs import (CONSTANT_SPECS, IOR_WATER, Constants, ShaderInputs, fresnel_lut,
                      fresnel_unpolarized, ortho_tex_matrix, perspective_view_proj)

__all__ = ["CONSTANT_SPECS", "IOR_WATER", "Constants", "ShaderInputs", "fresnel_lut",
           "fresnel_unpolarized", "ortho_tex_matrix", "perspective_view_proj"]
