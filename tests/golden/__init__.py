"""Golden images and the code that regenerates them (``python tests/golden/<module>.py``);
the tests import ``golden.regenerate`` and ``golden.reference_scenes``."""
