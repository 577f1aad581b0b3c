"""Text-conditioned motion diffusion: denoiser backbones, noise schedules, samplers, training, PhysDiff."""
