"""What OpenGL does around a fragment shader, in Dr.Jit, shared by the hand ports
(``shaders_port.ports``) and the SPIR-V executor (``shaders_port.spirv``): ``raster`` (the
water quad rasterised, each pixel's varyings), ``texture`` (GL texture sampling and the GLSL
built-ins ``mix``, ``clamp``, ``pow``) and ``frame`` (the output frame, constants, forward-mode
Jacobian passes and frozen kernels).
"""
