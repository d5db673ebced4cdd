"""The seed's real-time water shaders: GLSL sources and their Dr.Jit ports.

This layer takes plain inputs (textures, camera, constants) and knows nothing of
experiments, Mitsuba scenes or solvers. Ports: ``water_refraction``, ``water_reflection``,
``water_baseline`` (seeds 001-004)
(import the modules; they need Dr.Jit). GLSL: ``glsl_path``, ``read_source``,
``write_constants``, ``read_constants``, ``compile_check``. Running the GLSL headless on
OpenGL: ``shaders_port._gl.GLRenderer`` (imported lazily: it needs EGL).
"""

from ._glsl import (
    compat_to_core,
    compile_check,
    glsl_path,
    read_constants,
    read_source,
    write_constants,
)
from ._inputs import (
    CONSTANT_SPECS,
    IOR_WATER,
    Constants,
    ShaderInputs,
    fresnel_lut,
    fresnel_unpolarized,
    ortho_tex_matrix,
    perspective_view_proj,
)

__all__ = [
    "CONSTANT_SPECS",
    "IOR_WATER",
    "Constants",
    "ShaderInputs",
    "fresnel_lut",
    "fresnel_unpolarized",
    "ortho_tex_matrix",
    "perspective_view_proj",
    "compat_to_core",
    "compile_check",
    "glsl_path",
    "read_constants",
    "read_source",
    "write_constants",
]
