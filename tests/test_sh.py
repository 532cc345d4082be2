"""Spherical harmonics in the 3D-GS basis: the basis against an independent construction,
orthonormality, shared coefficients and gradients."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.special import lpmv

from gsseg.model.sh import eval_sh, sh_basis
from gsseg.model.sh_cpu import eval_sh_cpu


def fibonacci_sphere(n: int) -> np.ndarray:
    """(n, 3) nearly uniform unit vectors."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = math.pi * (1 + 5**0.5) * i
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


def real_sh_from_legendre(degree: int, m: int, dirs: np.ndarray) -> np.ndarray:
    """3D-GS's real SH of degree ``degree``, order m: sqrt(2) times the real (m > 0) or imaginary
    (m < 0) part of the complex SH with the Condon-Shortley phase, built from scipy's
    associated Legendre functions."""
    theta, phi = np.arccos(np.clip(dirs[:, 2], -1, 1)), np.arctan2(dirs[:, 1], dirs[:, 0])
    a = abs(m)
    norm = math.sqrt((2 * degree + 1) / (4 * math.pi) * math.factorial(degree - a) / math.factorial(degree + a))
    legendre = norm * lpmv(a, degree, np.cos(theta))
    if m == 0:
        return legendre
    return math.sqrt(2) * legendre * (np.cos(a * phi) if m > 0 else np.sin(a * phi))


def test_the_basis_equals_the_real_sh_of_3dgs_built_from_legendre_functions():
    dirs = fibonacci_sphere(500)
    basis = sh_basis(3, torch.as_tensor(dirs)).numpy()
    orders = [(degree, m) for degree in range(4) for m in range(-degree, degree + 1)]
    expected = np.stack([real_sh_from_legendre(degree, m, dirs) for degree, m in orders], -1)
    assert basis == pytest.approx(expected, abs=1e-12)
    for degree in range(3):  # lower degrees are the first (degree + 1)^2 columns
        assert np.array_equal(sh_basis(degree, torch.as_tensor(dirs)).numpy(), basis[:, : (degree + 1) ** 2])


def test_the_basis_is_orthonormal_over_the_sphere():
    dirs = torch.as_tensor(fibonacci_sphere(100_000))
    basis = sh_basis(3, dirs)
    gram = 4 * math.pi * basis.T @ basis / len(dirs)
    assert gram.numpy() == pytest.approx(np.eye(16), abs=1e-3)


def test_shared_coefficients_equal_the_same_coefficients_per_direction():
    gen = torch.Generator().manual_seed(0)
    dirs = torch.nn.functional.normalize(torch.randn(50, 3, generator=gen), dim=-1)
    coeffs = 0.3 * torch.randn(16, 3, generator=gen)
    for degree in range(4):
        assert torch.allclose(
            eval_sh(degree, coeffs, dirs), eval_sh(degree, coeffs.expand(50, -1, -1), dirs), atol=1e-6
        )


def test_eval_sh_gradients_match_finite_differences():
    """In coefficients and directions (which carry the gradient on to the Gaussians'
    positions), away from the clamp at 0."""
    gen = torch.Generator().manual_seed(1)
    dirs = torch.nn.functional.normalize(torch.randn(6, 3, generator=gen, dtype=torch.float64), dim=-1)
    coeffs = 0.1 * torch.randn(6, 16, 3, generator=gen, dtype=torch.float64)
    for degree in range(4):
        assert torch.autograd.gradcheck(
            lambda c, d: eval_sh(degree, c, d), (coeffs.clone().requires_grad_(), dirs.clone().requires_grad_())
        )
        assert torch.autograd.gradcheck(
            lambda c, d: eval_sh(degree, c, d), (coeffs[0].clone().requires_grad_(), dirs.clone().requires_grad_())
        )


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_cpu_kernels_match_the_tensor_colours_and_gradients(degree):
    """:func:`eval_sh_cpu` equals :func:`eval_sh` in float64, some colours clamped at 0, and so
    do the gradients of a loss on the colours with respect to the coefficients and to the
    directions (unit or not: the basis polynomials' own gradient)."""
    gen = torch.Generator().manual_seed(degree)
    dirs = torch.nn.functional.normalize(torch.randn(500, 3, generator=gen, dtype=torch.float64), dim=-1)
    coeffs = torch.randn(500, 16, 3, generator=gen, dtype=torch.float64)
    weights = torch.randn(500, 3, generator=gen, dtype=torch.float64)
    results = []
    for evaluate, dtype in ((eval_sh, torch.float64), (eval_sh_cpu, torch.float32)):
        c, d = (x.detach().to(dtype).requires_grad_(True) for x in (coeffs, dirs))
        colours = evaluate(degree, c, d)
        (colours * weights.to(dtype)).sum().backward()
        d_grad = torch.zeros_like(dirs) if d.grad is None else d.grad.double()  # degree 0: no path to d
        results.append((colours.double(), c.grad.double(), d_grad))
    (ref, ref_c, ref_d), (out, grad_c, grad_d) = results
    assert (ref == 0).any() and ref.max() > 0
    torch.testing.assert_close(out, ref, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(grad_c, ref_c, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(grad_d, ref_d, atol=1e-4, rtol=1e-4)
    assert (grad_c[:, (degree + 1) ** 2 :] == 0).all() and (degree == 0) == (ref_d == 0).all()
