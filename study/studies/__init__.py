"""Studies built on the fit and the scenes: failure catalogue (``failures``)."""
