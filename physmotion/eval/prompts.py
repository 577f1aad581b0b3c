"""Fixed prompt sets for evaluations and benchmarks.

``PHYSICS_PROMPTS``: 32 captions in the words of our data's captions (Bandai and CMU), covering
locomotion, gestures and whole-body actions, used to compare --physics none / post / physdiff.
"""

PHYSICS_PROMPTS: tuple[str, ...] = (
    "a person walks forward",
    "a person runs forward",
    "a person jumps",
    "a person kicks",
    "a person waves goodbye with one hand",
    "a person waves goodbye with both hands",
    "a person walks backwards",
    "a person walks sideways to the left",
    "a person walks sideways to the right",
    "a person walks and turns left",
    "a person walks and turns right",
    "a person dashes forward",
    "a person bows",
    "a person raises both hands",
    "a person raises the right hand",
    "a person walks forward in a tired manner",
    "a person walks forward in a happy manner",
    "a person walks like an old person",
    "a person runs forward in an active manner",
    "a person walks forward in a proud manner",
    "a person dribbles a basketball",
    "a person gestures with the hands while guiding",
    "a person walks forward like a heavy giant",
    "a person walks forward in a childish manner",
    "a person jogs forward",
    "a person walks slowly",
    "a person runs in a sad manner",
    "a person waves the right hand",
    "a person fights with a sword",
    "a person walks forward in a feminine manner",
    "a person throws punches",
    "a person starts walking, then stops",
)
