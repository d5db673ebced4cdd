"""GLSL through SPIR-V: ``tools`` (glslang, SPIRV-Tools and SPIRV-Cross run as programs: the
engine targets and the HLSL round trip) and the executor that renders and differentiates any
GLSL water shader on Dr.Jit types without a hand port: ``translated`` (a shader compiled and
run, the study's variants through it), ``module`` (SPIR-V decoded with the grammar),
``execute`` (the instructions run), ``ops`` (their arithmetic), ``loops`` (their loops) and
``user_shader`` (a user's own shader file, declared, rendered and written back).
"""
