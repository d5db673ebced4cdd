"""The fit stage: the port against a reference (``model``), the Dr.Jit residual seen by JAX
(``jax_residual``), the solvers behind one loop (``solver_loop``, ``solvers``),
identifiability, the calibration of one experiment (or several, ``joint``) and the decorrelated
loss that cancels the texture's noise (``decorrelated``)."""
