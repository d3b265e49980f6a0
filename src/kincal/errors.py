"""The one exception hierarchy of kincal.

Every error a user can cause is a :class:`KincalError`. Subclasses say which
boundary rejected the input; messages say what is wrong, where, and what was
expected, and the exception keeps the evidence as attributes.
"""

from __future__ import annotations


class KincalError(Exception):
    """Root of every error kincal raises on purpose."""


class InputFileError(KincalError):
    """A file is missing, unreadable, or not what its extension promises."""


class UrdfError(KincalError):
    """A URDF that cannot be used: malformed XML, xacro left in, unsafe constructs."""


class FrameError(KincalError):
    """An unknown frame or joint name, or a base/tip pair that is not a chain.

    ``valid`` holds the names that would have been accepted.
    """

    def __init__(self, message: str, valid: tuple[str, ...] = ()):
        super().__init__(message)
        self.valid = tuple(valid)


class ChainError(KincalError):
    """A chain kincal cannot model (a floating or planar joint on it, no movable joint)."""


class ParameterError(KincalError):
    """An unknown parameter name or an invalid parameter value."""

    def __init__(self, message: str, valid: tuple[str, ...] = ()):
        super().__init__(message)
        self.valid = tuple(valid)


class DataError(KincalError):
    """Measurement data that cannot be used: missing columns, NaN, too few poses."""


class IdentifiabilityError(KincalError):
    """The data cannot identify what was asked (rank too low)."""


class OptionError(KincalError):
    """An option out of range (folds, lambda grid, tolerances)."""


class PriorError(KincalError):
    """A fleet prior (FLEET.json) that is malformed or belongs to another robot, error model
    or parameter set."""


class ExportError(KincalError):
    """The corrected URDF or frames file could not be written."""


class ImplausibleResultError(KincalError):
    """A calibration whose corrections or residuals are implausible (wrong units, rows,
    tip or data); nothing is written. ``plausibility`` holds the findings and evidence."""

    def __init__(self, message: str, plausibility=None):
        super().__init__(message)
        self.plausibility = plausibility


class NotConvergedError(KincalError):
    """A calibration whose solver did not converge; nothing is written unless accepted.
    ``plausibility`` holds the evidence."""

    def __init__(self, message: str, plausibility=None):
        super().__init__(message)
        self.plausibility = plausibility


def suggest(name: str, valid, n: int = 3) -> str:
    """A ' Did you mean ...?' hint for a misspelled ``name`` among ``valid``."""
    import difflib

    close = difflib.get_close_matches(name, list(valid), n=n, cutoff=0.6)
    if not close:
        return ""
    return " Did you mean " + " or ".join(repr(c) for c in close) + "?"


def listing(valid, limit: int = 40) -> str:
    """The valid names as a short comma-separated listing for a message."""
    valid = list(valid)
    text = ", ".join(valid[:limit])
    if len(valid) > limit:
        text += f", ... ({len(valid) - limit} more)"
    return text


class KincalWarning(UserWarning):
    """Something the user should know that does not stop the run (weak parameters, units)."""


class KincalNote(KincalWarning):
    """How an input was read, when kincal had to guess (a sniffed CSV separator).

    The command line prints these as ``kincal: note: ...``; nothing is wrong.
    """
