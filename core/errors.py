"""Errors raised by core for bad input; each message names the culprit (polygon, vertex, argument)."""


class VisradError(Exception):
    """Base class of every error core raises on purpose."""


class SceneError(VisradError, ValueError):
    """The scene description is invalid; the message names the offending polygon, vertex or array."""


class CancelledError(VisradError):
    """A long stage was cancelled by its cancel() callback; the object keeps its last consistent state."""
