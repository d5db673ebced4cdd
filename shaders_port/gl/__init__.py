"""The GLSL run on a real OpenGL (headless EGL, Mesa llvmpipe): ``renderer`` (``GLRenderer``),
``contexts`` (core-profile, compatibility-profile and OpenGL ES contexts for moderngl),
``dialect`` (the water quad on a compatibility or ES context, after the study's vertex shader
in the fragment shader's GLSL version), ``grid`` (a user's vertex shader over the water grid),
``round_trip`` (the HLSL translated back by SPIRV-Cross, run with its renamed inputs) and
``compare`` (a port against the GLSL, outliers explained by the port's diagnostics).

Import the modules themselves; they need EGL.
"""
