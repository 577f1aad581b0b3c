"""Datasets in HumanML3D's folder layout: building one from mocap, reading it for training, its statistics."""
