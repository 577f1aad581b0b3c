"""Frozen text encoders that turn captions into the features the denoiser and the evaluator read."""
