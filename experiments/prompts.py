"""Fixed prompt sets for the experiments (physdiff_quality, generate_speed, imitator).

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

# Prompts written from scratch for the unseen-prompt benchmark (Morph and the dynamic-motion projection):
# none is a train caption (tests/experiments/test_prompts.py checks), each category has at least 4, and runs and
# jumps are categories of their own so that their rows can be read alone.
NEW_PROMPTS: dict[str, tuple[str, ...]] = {
    "run": ("someone sprints straight ahead", "a man runs quickly across the room",
            "a runner speeds up and then slows down", "a woman runs in a wide circle"),
    "jog": ("a person jogs slowly in place", "someone jogs forward at an easy pace",
            "a jogger moves forward and glances around", "a person jogs a few steps and stops"),
    "jump": ("a person jumps forward with both feet", "someone leaps high into the air",
             "a person does three small jumps in a row", "a man jumps over a puddle"),
    "hop": ("a person hops on the left foot", "someone hops forward on one leg",
            "a child hops around happily", "a person hops from side to side"),
    "kick": ("a person kicks high with the right leg", "someone kicks a ball forward",
             "a fighter does a front kick", "a person kicks twice with the left foot"),
    "turn": ("a person spins around once", "someone turns around on the spot",
             "a person pivots to face the other way", "a dancer twirls in place"),
    "dance": ("a person dances energetically", "someone does a little dance with the arms up",
              "a person sways to music", "a person dances and claps"),
    "gesture": ("a person claps the hands", "someone points to the left", "a person shrugs the shoulders",
                "a person stretches both arms above the head"),
    "stand": ("a person stands still", "someone stands and looks around",
              "a person waits in place shifting weight", "a person stands and scratches the head"),
}
