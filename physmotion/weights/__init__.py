"""Shipped model weights (safetensors) with their model cards; see ``default/README.md``."""
