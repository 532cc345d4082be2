"""The model: Gaussians and their PLY files, spherical harmonics, the learned background
(environment), and their CPU kernels."""
