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

FLOOR_JOINTS: str = "joints"
"""Floor convention of HumanML3D's features: each clip's lowest *joint* on y = 0 (``process_file``). It
leaves the humanoid's soles about 2.5 cm under the floor (docs/decisions/data.md: "floor convention")."""

FLOOR_SURFACE: str = "surface"
"""Floor convention of physical motion: the humanoid's soles on y = 0, as P's simulated motions stand.
A model fine-tuned on motions in it (Morph, ``FinetuneConfig.floor``) samples in it; the model's
``info["floor"]`` says which of the two it learned (absent: FLOOR_JOINTS)."""

FLOORS: tuple[str, ...] = (FLOOR_JOINTS, FLOOR_SURFACE)


def check_floor(floor: str) -> str:
    """``floor`` if it names a floor convention, else ValueError (a programming error, not a user's)."""
    if floor not in FLOORS:
        raise ValueError(f"floor convention must be one of {FLOORS}, got {floor!r}")
    return floor


CFG_SCALE_RANGE: tuple[float, float] = (0.0, 10.0)
"""Classifier-free guidance scales a sampler accepts. The guided estimate is ``u + s * (c - u)``
(diffusion/samplers.py ``guided_x0``): 0 is the unconditional model, 1 the text-conditioned one, above 1
extrapolates past it (MDM's default is 2.5). A negative scale steers *away* from the text, and a scale far
above MDM's pushes the estimate off the data (issue 62 reports ``--cfg-scale -100`` giving a body 41 cm
off the floor moving at 11.6 m/s). Ten is four times MDM's default, a generous upper end."""
