"""The GLSL run on a real OpenGL (headless EGL, Mesa llvmpipe): ``renderer`` (``GLRenderer``),
``round_trip`` (the HLSL translated back by SPIRV-Cross, run with its renamed inputs) and
``compare`` (a port against the GLSL, outliers explained by the port's diagnostics).

Import the modules themselves; they need EGL.
"""
