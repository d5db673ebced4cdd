"""The fit stage: the port against a reference (``model``), the JAX/Dr.Jit bridge, solvers,
identifiability, the calibration of one experiment (or several, ``joint``) and the decorrelated
loss that cancels the texture's noise (``decorrelated``)."""
