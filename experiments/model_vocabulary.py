"""Write a model folder's vocabulary.txt: the words of the captions it was trained on.

A tool rather than an experiment: it writes into the model folder, not into results/.

    python -m experiments.model_vocabulary --data data_build/all --model physmotion/weights/base

`physmotion generate` warns about prompt words outside this file (physmotion/text/vocabulary.py).
--max-frames is the length filter of the training run (the base model's: 196, every window; its
step-8304 predecessor's was 120, when the crop also filtered); the script checks the motion count
against the model's config.json (info.train_items) and refuses a mismatch, so the file describes what
the model saw.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from physmotion.conventions import MAX_FRAMES
from physmotion.diffusion.model import BASE_MODEL_DIR
from physmotion.errors import PhysmotionError
from physmotion.text.vocabulary import VOCABULARY_FILE, training_vocabulary, write_vocabulary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="the HumanML3D-layout folder the model was trained on")
    parser.add_argument("--model", default=str(BASE_MODEL_DIR), help="model folder (default: the shipped base model, trained on the build)")
    parser.add_argument("--max-frames", type=int, default=MAX_FRAMES, help="the run's length filter")
    parser.add_argument("--split", default="train")
    args = parser.parse_args(argv)
    try:
        counts, motions = training_vocabulary(args.data, args.max_frames, args.split)
        config = Path(args.model) / "config.json"
        expected = json.loads(config.read_text()).get("info", {}).get("train_items") if config.is_file() else None
        if expected is not None and expected != motions:
            raise PhysmotionError(f"{args.data} gives {motions} {args.split} motions with --max-frames "
                                  f"{args.max_frames}; {config} says the model trained on {expected}")
        out = Path(args.model) / VOCABULARY_FILE
        header = (f"Words of the {args.split} captions this model was trained on ({motions} motions of "
                  f"{Path(args.data).name}, under {args.max_frames + 4} frames).\n"
                  "Written by experiments/model_vocabulary.py; read by physmotion generate.")
        write_vocabulary(out, counts, header)
    except PhysmotionError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {out}: {len(counts)} words from {motions} motions")
    return 0


if __name__ == "__main__":
    sys.exit(main())
