"""Which captions describe motion the flat-floor simulation can reproduce ("grounded").

Morph (App. A, Sec. 3.3) annotates each HumanML3D caption by hand: interaction or non-grounded motion
(sitting down, climbing stairs, swimming) is labelled 0 and kept out of the physics refinement's
training; the imitation selection keeps the generated input for them. We have no such annotation, so a
caption is flagged by rule: it is non-grounded where it names a support, an environment or a way of
moving that the simulation (one humanoid on a flat floor, no objects) does not have.
"""

from __future__ import annotations

import re

# Each entry: words (matched whole, case-insensitive, any inflection listed) and why they break the
# flat-floor simulation. Phrases match as written, with any run of spaces/hyphens between words.
NON_GROUNDED_RULES: tuple[tuple[tuple[str, ...], str], ...] = (
    (("sit", "sits", "sitting", "sat", "seated", "chair", "stool", "bench", "sofa", "couch", "seat"),
     "needs a seat the simulation does not have"),
    (("lie", "lies", "lying", "lay", "lays", "laying", "bed"), "rests on a bed or the ground with the torso"),
    (("climb", "climbs", "climbing", "stairs", "stair", "staircase", "steps up", "steps down", "ladder",
      "ladders", "upstairs", "downstairs"), "needs steps or a ladder, not a flat floor"),
    (("swim", "swims", "swimming", "breaststroke", "freestyle stroke"), "in water: no ground contact"),
    (("crawl", "crawls", "crawling", "on all fours", "on hands and knees"),
     "hands and knees carry the body; the tracker is tuned for feet"),
    (("kneel", "kneels", "kneeling", "knelt"), "knees on the ground carry the body"),
    (("ride", "rides", "riding", "bicycle", "bike", "horse", "skateboard", "scooter"),
     "carried by a vehicle or animal"),
    (("lean on", "leans on", "leaning on", "leans against", "leaning against", "wall", "table", "railing",
      "rail", "handrail"), "supported by an object"),
    (("push-up", "push-ups", "pushup", "pushups", "sit-up", "sit-ups", "situp", "situps", "plank"),
     "floor exercise on hands or back"),
    (("hang", "hangs", "hanging", "monkey bars", "pull-up", "pull-ups", "pullup",
      "swinging on", "swings on"), "hangs from something above"),
    (("terrain", "uneven", "slope", "hill", "ramp", "obstacle", "box", "platform", "ledge", "curb",
      "stepping stones"), "uneven or raised ground: the simulation's floor is flat"),
    (("carry", "carries", "carrying", "lift a", "lifts a", "picks up a", "pushes a", "pulls a", "drag",
      "drags", "dragging"), "moves a heavy object the simulation does not have"),
)

_PATTERNS: tuple[re.Pattern[str], ...] = tuple(
    re.compile(r"(?<![a-z])" + r"[\s\-]+".join(map(re.escape, re.split(r"[\s\-]+", phrase))) + r"(?![a-z])")
    for words, _ in NON_GROUNDED_RULES
    for phrase in words
)


def non_grounded_reason(caption: str) -> str | None:
    """Why ``caption`` is not grounded (the first rule it matches), or None where it is grounded."""
    text = caption.lower()
    k = 0
    for words, why in NON_GROUNDED_RULES:
        for _ in words:
            if _PATTERNS[k].search(text):
                return why
            k += 1
    return None


def is_grounded(caption: str) -> bool:
    """True where the caption describes motion on a flat floor that the simulation can reproduce."""
    return non_grounded_reason(caption) is None
