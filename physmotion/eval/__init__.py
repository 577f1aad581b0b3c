"""Evaluation: prompt sets and physical comparisons of generation modes."""
