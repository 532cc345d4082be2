"""The front-to-back blending rules of 3D-GS, shared by every backend."""

ALPHA_MAX = 0.99  # opacity clamp of one Gaussian at one pixel
ALPHA_MIN = 1.0 / 255.0  # Gaussians fainter than this at a pixel are skipped
T_MIN = 1e-4  # blending stops before transmittance would fall below this
