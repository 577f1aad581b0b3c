"""One class per generation method, each call returning a result object (no state left behind):

- :class:`~physmotion.pipelines.plain.PlainPipeline` (``none``) and
  :class:`~physmotion.pipelines.plain.FloorPipeline` (``none+floor``): plain sampling, as sampled or grounded;
- :class:`~physmotion.pipelines.physdiff.PhysDiffPipeline` (``physdiff[:SCHEDULE]``) and
  :class:`~physmotion.pipelines.physdiff.PostProjectionPipeline` (``post[:K]``): PhysDiff and its baseline;
- :class:`~physmotion.pipelines.morph.MorphPipeline` (``morph``): Morph's inference;
- :class:`~physmotion.pipelines.refine.RefinePipeline`: BioMoDiffuse's refinement of a given motion.

:mod:`physmotion.pipelines.modes` names the methods (``PhysicsMode``); ``physmotion.generate`` picks the
pipeline of a mode and writes the files. Submodules are imported where used: importing this package loads
nothing heavy.
"""
