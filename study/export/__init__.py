"""The export stage: fitted constants written into the shipped GLSL (``shaders``), the exported
shaders translated into the engines' languages (``targets``) with a binding sheet for each
(``bindings``), and the exported shaders run on llvmpipe against the Dr.Jit port
(``gl_check``)."""
