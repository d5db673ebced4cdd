"""The calibration pipeline, written once for every command and sweep: the frames a fit runs
over (``frames``: a still experiment is a list of one; views, an animation's frames and several
experiments are longer lists), the shader they are fitted for (``shader``: one handle for the
study's ports and a user's GLSL file), the fit with its explicit options (``fitting``), the
score of a frame at full resolution (``scoring``), the export with its GL check (``export``)
and the one builder of the ``CalibrationResult`` (``result``)."""
