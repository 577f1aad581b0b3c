"""The one source of truth for the project's conventions (units, axes, rates, windows)."""

FPS: int = 20
"""Frame rate of datasets and generation (HumanML3D)."""

UP_AXIS: int = 1
"""World up axis index: Y up. The floor is the plane y = 0; bodies face +Z at frame 0."""

MAX_FRAMES: int = 196
"""Longest training window in frames at FPS (HumanML3D: 9.8 s)."""

MIN_FRAMES: int = 40
"""Shortest clip or window kept in a dataset (HumanML3D: 2 s)."""

MAX_TEXT_TOKENS: int = 32
"""Tokens of a caption the text encoder reads (special tokens included); the rest is cut off. Our
captions are short; HumanML3D's are under 30 words."""
