"""Morph (Zhang et al.): generate synthetic motions, refine them with the physics projection P, keep the
refined motion where P imitated it, and fine-tune the generator on the result.

- :mod:`physmotion.morph.captions`: which captions describe grounded motion (rule list).
- :mod:`physmotion.morph.synth`: the synthetic data set (``SYNTH/`` folder) and its refinement by P.
- :mod:`physmotion.morph.selection`: Morph's imitation selection over a ``SYNTH/`` folder (Sec. 3.3).
"""
