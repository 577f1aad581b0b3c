"""The length model on captions it has not seen: a split by caption of the build's examples.

    python -m experiments.length_split --data data_build/all [--model physmotion/weights/length] [--seed 0]
        [--out results/length_split]

The build's splits keep a clip on one side, not a caption: HDM05 gives every clip of a class one caption,
so most test captions are in train too and the card's test MAE measures captions the model saw. Here the
examples (:func:`physmotion.text.length.length_examples`) are split so that no caption and no clip is on
two sides (:func:`physmotion.text.length.caption_split`, seeded). A model is refit on that split's train +
val exactly as ``physmotion train length`` fits the shipped one, and measured on its test side; the
shipped model is measured there too, with the number of those test captions it was fit on. No projection
(the meta's preset is null). Writes ``<out>.md`` and ``<out>.json``.
"""

from __future__ import annotations

import argparse
from dataclasses import asdict
from pathlib import Path

from experiments._results import heading, markdown_table, parse_args, report, run_meta, write_results
from physmotion.text.length import (
    CAPTION_SPLIT_SEED,
    LENGTH_MODEL_DIR,
    LengthPredictor,
    caption_split_report,
    encode_examples,
    length_examples,
)

SHIPPED = Path(*LENGTH_MODEL_DIR.parts[-3:])  # physmotion/weights/length, as the meta names it


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path("data_build/all"), help="a `data build` folder")
    parser.add_argument("--model", type=Path, default=None, help="the length model measured (default: the "
                        f"shipped one, {SHIPPED})")
    parser.add_argument("--seed", type=int, default=CAPTION_SPLIT_SEED)
    parser.add_argument("--out", type=Path, default=Path("results/length_split"))
    args = parse_args(parser, argv)

    def run() -> tuple[str, list[Path]]:
        examples = length_examples(args.data)
        model = LengthPredictor.load(args.model)
        r = caption_split_report(examples, encode_examples(examples, model.encoder), model, seed=args.seed,
                                 encoder=model.encoder)  # fmt: skip
        n = r.examples["test"]
        table = markdown_table(("test side of the split by caption", "MAE, s"), [
            (f"refit on its train + val (ridge {r.refit_alpha:g})", f"{r.refit_test_mae:.2f}"),
            (f"the model given (fit on the build's train + val: saw {r.test_captions_seen} of the {n} "
             "captions)", f"{r.model_test_mae:.2f}"),
            ("constant 6 s", f"{r.test_mae_const6:.2f}"),
            ("constant: its train examples' mean", f"{r.test_mae_mean:.2f}"),
        ])  # fmt: skip
        meta = run_meta(__file__, argv, args.tree, None, data=str(args.data), model=str(args.model or SHIPPED),
                        seed=args.seed)
        sides = ", ".join(f"{r.examples[s]} {s} examples in {r.groups[s]} groups" for s in r.examples)
        md = heading("The length model on unseen captions (a split by caption)", meta) + (
            f"No caption and no clip on two sides: {sides}.\n\n{table}\n")
        return table, write_results(args.out, md, {"meta": meta, "caption_split": asdict(r)})

    return report(run)


if __name__ == "__main__":
    raise SystemExit(main())
