"""How physics enters generation: one typed mode, one parser, one spelling everywhere.

Spellings (``generate --physics``, ``evaluate --physics`` as a comma list, table rows):

- ``none``: plain diffusion sampling, measured as sampled (the papers' baseline);
- ``none+floor``: plain sampling, then each motion moved up or down onto the floor by the constant
  that leaves it the least Phys-Err on the body's surface
  (:func:`physmotion.physics.surface.ground_on_surface`): the clean-up any user does first, at its best,
  and the fair baseline for the physics modes;
- ``post[:K]``: K applications of P after sampling (default 1), the post-processing baseline;
- ``physdiff[:SCHEDULE]``: PhysDiff's Algorithm 2, P inside sampling at the steps of SCHEDULE
  (``uniform:N``, ``start:M,end:N`` or ``end:N,space:S``; PhysDiff's own, ``end:4,space:1``, is for 50
  DDIM steps), optionally with ``fly:last``: a motion that flies is projected at the last scheduled step
  only. Default ``end:2,space:1,fly:last``: the last two of the default 10 steps, a flying motion the last;
- ``morph``: Morph's inference (Sec. 3.3 "Inference"): plain sampling, then one P with Morph's imitation
  selection (``ProjectionConfig()``: no reset; where the imitation fails, MPJPE past tau = 0.5 m, the
  sampled motion is kept and counted as an imitation failure). Meant for a Morph fine-tuned model, and
  runs with any.
"""

from __future__ import annotations

from dataclasses import dataclass

from physmotion.errors import PhysmotionError

NONE, FLOOR, POST, PHYSDIFF, MORPH = "none", "none+floor", "post", "physdiff", "morph"
KINDS = (NONE, FLOOR, POST, PHYSDIFF, MORPH)
# The last two of the default sampler's 10 steps, at the noise levels of PhysDiff's own choice, the last
# four of 50 DDIM steps (docs/decisions/sampling.md: "few-step sampling as the default"); a motion that
# flies only the last (docs/decisions/sampling.md: "PhysDiff with one P at the end for a motion that flies").
DEFAULT_SCHEDULE = "end:2,space:1,fly:last"
MAX_POST_PROJECTIONS = 50
_USAGE = "use none, none+floor, post[:K], physdiff[:SCHEDULE] or morph"


@dataclass(frozen=True)
class PhysicsMode:
    """A parsed mode. ``projections``: P's applications after sampling (post; 1 for morph); ``schedule``:
    PhysDiff's projection steps (physdiff). ``str(mode)`` gives the canonical spelling back."""

    kind: str = PHYSDIFF
    projections: int = 0
    schedule: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise PhysmotionError(f"unknown physics mode {self.kind!r}: {_USAGE}")
        if self.kind == PHYSDIFF and not self.schedule:
            object.__setattr__(self, "schedule", DEFAULT_SCHEDULE)
        if self.kind in (POST, MORPH) and not self.projections:
            object.__setattr__(self, "projections", 1)

    @classmethod
    def parse(cls, spec: str | PhysicsMode) -> PhysicsMode:
        """The mode of a spelling (see the module docstring); a mode passes through unchanged."""
        if isinstance(spec, PhysicsMode):
            return spec
        if not isinstance(spec, str):
            raise PhysmotionError(f"bad physics mode {spec!r}: {_USAGE}")
        kind, _, arg = spec.strip().partition(":")
        if kind in (NONE, FLOOR, MORPH) and not arg:
            return cls(kind)
        if kind == POST:
            try:
                count = int(arg) if arg else 1
            except ValueError:
                raise PhysmotionError(f"bad physics mode {spec!r}: post takes a count, e.g. post:4") from None
            if not 1 <= count <= MAX_POST_PROJECTIONS:
                raise PhysmotionError(
                    f"post projections must be between 1 and {MAX_POST_PROJECTIONS}, got {count}"
                )
            return cls(POST, projections=count)
        if kind == PHYSDIFF:
            return cls(PHYSDIFF, schedule=arg.replace(" ", ""))
        raise PhysmotionError(f"unknown physics mode {spec!r}: {_USAGE}")

    def __str__(self) -> str:
        if self.kind == POST:
            return f"{POST}:{self.projections}"
        if self.kind == PHYSDIFF:
            return f"{PHYSDIFF}:{self.schedule}"
        return self.kind

    @property
    def projects(self) -> bool:
        """P is applied (post, physdiff or morph)."""
        return self.kind in (POST, PHYSDIFF, MORPH)

    @property
    def flies_last(self) -> bool:
        """PhysDiff's schedule carries ``fly:last`` (:mod:`physmotion.diffusion.physdiff`)."""
        if self.kind != PHYSDIFF:
            return False
        from physmotion.diffusion.physdiff import flies_last

        return flies_last(self.schedule)

    def hook_steps(self, steps: int) -> list[int]:
        """Sampling-loop indices at which PhysDiff projects (empty for the other modes); raises
        PhysmotionError for a schedule that does not fit ``steps``."""
        if self.kind != PHYSDIFF:
            return []
        from physmotion.diffusion.physdiff import parse_schedule

        return parse_schedule(self.schedule, steps)


def parse_modes(spec: str) -> list[PhysicsMode]:
    """A comma list of modes: ``"none,post:4,physdiff:end:4,space:1"``. A schedule's own commas stay
    with it: a piece that does not start a mode joins the one before."""
    pieces: list[str] = []
    for piece in (p.strip() for p in spec.split(",")):
        if not piece:
            continue
        if piece.split(":")[0] in KINDS or not pieces:
            pieces.append(piece)
        else:
            pieces[-1] += "," + piece
    if not pieces:
        raise PhysmotionError("no physics mode given: e.g. --physics none,none+floor,post:1,physdiff")
    return [PhysicsMode.parse(p) for p in pieces]
