"""One error type for everything a user can get wrong; the CLI prints it as one line."""


class PhysmotionError(Exception):
    """Base of every user-facing error: bad input, missing files, wrong shapes."""


class MotionFormatError(PhysmotionError):
    """A motion file that cannot be read: truncated, not the claimed format, NaN values, no frames."""


class ShapeError(PhysmotionError):
    """An array whose shape or values do not fit what a function expects."""


class PhysmotionWarning(UserWarning):
    """Something a user should know that does not stop the work (an assumed value, a truncated input);
    the CLI prints it as one ``warning: ...`` line."""
