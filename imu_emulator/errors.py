"""Errors a user can act on. The CLI prints `error: <message>` on one line and exits non-zero."""


class ImuEmulatorError(Exception):
    """Base: anything that is the user's input, not our bug."""


class SceneError(ImuEmulatorError):
    """A scene file or scene object is malformed; the message names the key and the reason."""


class DataError(ImuEmulatorError):
    """Sampled input (CSV/NPZ/arrays) is unusable: non-finite values, bad time stamps, too few samples."""


class TargetError(ImuEmulatorError):
    """A stream target cannot be used: unknown kind, missing device, malformed spec, link too slow."""
