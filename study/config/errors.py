"""The error every bad experiment value raises, named by the key and the fix."""


class ExperimentError(ValueError):
    """An experiment file or override is invalid; the message names the key and the fix."""
