"""physmotion: text-to-motion generation that obeys physics."""

from physmotion.errors import PhysmotionError
from physmotion.motion import Motion

__all__ = ["Motion", "PhysmotionError"]
__version__ = "0.1.0"
