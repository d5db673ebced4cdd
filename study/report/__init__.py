"""The report stage: figures and report writers, GLSL export, and the exported shader checked on
llvmpipe."""
