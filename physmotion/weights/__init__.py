"""Shipped model weights (safetensors) with their model cards: ``morph/README.md`` (the default generator),
``base/README.md`` (the one it was fine-tuned from), ``evaluator``, ``imitator``, ``length``."""
