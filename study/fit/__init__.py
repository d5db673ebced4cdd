"""The fit stage: the port against a reference (``model``), the JAX/Dr.Jit bridge, solvers,
identifiability and the calibration of one experiment."""
