"""The error every bad experiment value raises, named by the key and the fix, and the clipping
of the values and paths such a message quotes."""


class ExperimentError(ValueError):
    """An experiment file or override is invalid; the message names the key and the fix."""


def clip_text(text: str, limit: int = 80) -> str:
    """``text`` cut to ``limit`` characters with the number of characters left out."""
    text = str(text)
    return (
        text if len(text) <= limit else f"{text[:limit]}... ({len(text) - limit} more characters)"
    )


def clip_path(path, limit: int = 240) -> str:
    """A path cut to its last ``limit`` characters (the file's name stays whole), marked."""
    text = str(path)
    return text if len(text) <= limit else f"...{text[-limit:]}"
