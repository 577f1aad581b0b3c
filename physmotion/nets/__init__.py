"""The networks of the diffusion models: MDM's transformer denoiser, BioMoDiffuse's UNet and physical network,
and what they share (``backbone``). The text encoder (``text/minilm.py``), the evaluator (``eval/evaluator.py``)
and the imitation policy (``physics/policy.py``) keep their networks beside the code that uses them."""
