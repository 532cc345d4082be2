"""Stages B and C: 3D Gaussian Splatting with object features, label reassignment, edits."""
