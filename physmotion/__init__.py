"""physmotion: text-to-motion generation that obeys physics."""

from physmotion.errors import PhysmotionError


def __getattr__(name: str):
    """``physmotion.Motion`` on first use: the command line starts without numpy (``--help``)."""
    if name == "Motion":
        from physmotion.motion import Motion

        return Motion
    raise AttributeError(f"module 'physmotion' has no attribute {name!r}")

__all__ = ["Motion", "PhysmotionError"]
__version__ = "0.1.0"
