"""Studies built on the sweep engine: ``tradeoff`` (speed against accuracy, Pareto fronts),
``failures`` (the shader's failure catalogue)."""
