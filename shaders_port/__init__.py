"""The seed's real-time water shaders: GLSL sources and their Dr.Jit ports.

This layer takes plain inputs (textures, camera, constants) and knows nothing of
experiments, Mitsuba scenes or solvers. Where things are:

* ``glsl/``: the GLSL files; ``glsl_text``: their paths, dialects, constants block and
  compile checks; ``inputs``: the plain inputs (``ShaderInputs``, ``Constants``);
* ``variants``: the registry of shader variants; ``space``: the shader space they are points of;
* ``ports/``: the hand ports ``water_refraction``, ``water_reflection``, ``water_baseline``
  (seeds 001-004) (import the modules; they need Dr.Jit);
* ``pipeline/``: rasterisation, texture sampling and the output frame, shared by the ports and
  the SPIR-V executor;
* ``spirv/``: the SPIR-V tools and the executor that runs any GLSL shader without a port;
* ``gl/``: the GLSL run headless on OpenGL, ``shaders_port.gl.renderer.GLRenderer`` (imported
  lazily: it needs EGL), and the port-against-GL comparison.

Re-exported here: ``glsl_path``, ``read_source``, ``write_constants``, ``read_constants``,
``compile_check``, ``compat_to_core`` and the inputs below.
"""

from .glsl_text import (
    compat_to_core,
    compile_check,
    glsl_path,
    read_constants,
    read_source,
    write_constants,
)
from .inputs import (
    CONSTANT_SPECS,
    GLSL_NAMES,
    IOR_WATER,
    Constants,
    ShaderInputs,
    fresnel_lut,
    fresnel_unpolarized,
    glsl_scalar,
    ortho_tex_matrix,
    perspective_view_proj,
    study_scalar,
)

__all__ = [
    "CONSTANT_SPECS",
    "GLSL_NAMES",
    "IOR_WATER",
    "Constants",
    "ShaderInputs",
    "fresnel_lut",
    "fresnel_unpolarized",
    "glsl_scalar",
    "ortho_tex_matrix",
    "perspective_view_proj",
    "study_scalar",
    "compat_to_core",
    "compile_check",
    "glsl_path",
    "read_constants",
    "read_source",
    "write_constants",
]
