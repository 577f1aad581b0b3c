"""Experiments: one script per study or benchmark, each run from the repository's root as
``python -m experiments.<name>`` and writing ``results/<name>.md`` and ``.json`` (experiments/README.md)."""
