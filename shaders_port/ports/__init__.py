"""The hand ports: each GLSL fragment shader of ``shaders_port/glsl/`` written line by line in
Dr.Jit, with the same file name and block banners (``water_refraction``, ``water_reflection``,
``water_baseline``), and what only they use: ``switches`` (a variant's ``#define`` names ->
a port's options) and ``planar`` (seed 004's mirrored camera, shared by two ports). The tests'
slow per-pixel NumPy reference of the raycast shaders is ``tests/helpers/numpy_ref.py``.

Import the modules themselves; they need Dr.Jit.
"""
