"""The rasterizer: the compiled ``cpu`` backend against the ``torch`` reference, the reference
against finite differences, and known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from helpers import GEOMETRY, look_down_z, output_weights, random_gaussians, weighted_sum

from dataset_tools.cameras import PinholeCamera
from gsseg.model.gaussians import Gaussians
from gsseg.render import BACKENDS, cpu_kernels, get_backend, render
from gsseg.render.cpu_projection import project_gaussians_cpu
from gsseg.render.projection import project_gaussians

OUTPUTS = ("rgb", "features", "alpha", "depth")


def _render_with_grads(g: Gaussians, backend: str, weights, cam, pose):
    g = Gaussians(**{k: v.clone().requires_grad_(True) for k, v in g.tensors().items()})
    out = render(g, cam, pose, backend=backend)
    weighted_sum(out, weights).backward()
    return out, {k: v.grad for k, v in g.tensors().items()}


@pytest.mark.parametrize(
    "seed, n, size, scales",
    [
        (0, 150, (40, 32), (0.04, 0.24)),
        (1, 150, (40, 32), (0.04, 0.24)),
        (2, 150, (40, 32), (0.04, 0.24)),
        # small, elongated Gaussians over many tiles: the cpu kernels visit only the rows of a
        # tile that a Gaussian's footprint reaches, and tiles at the image border are partial
        (3, 400, (90, 70), (0.005, 0.08)),
    ],
)
def test_cpu_backend_matches_torch_reference(seed, n, size, scales):
    cam, pose = look_down_z(*size)
    g = random_gaussians(n, seed, scales=scales)
    weights = output_weights(cam.width, cam.height, seed, torch.float32)
    ref, ref_grads = _render_with_grads(g, "torch", weights, cam, pose)
    out, grads = _render_with_grads(g, "cpu", weights, cam, pose)
    # The scene exercises the 0.99 opacity clamp and the early stop at T < 1e-4.
    assert torch.sigmoid(g.opacity_logits).max() > 0.99 and ref.alpha.max() > 0.9998
    for name in OUTPUTS:
        torch.testing.assert_close(getattr(out, name), getattr(ref, name), atol=1e-4, rtol=0)
    for name, expected in ref_grads.items():
        rel = (grads[name] - expected).norm() / expected.norm()
        assert expected.norm() > 0 and rel < 1e-3, (name, rel.item())


@pytest.mark.parametrize("backend", ["cpu", "torch"])
def test_features_without_geometry_grad_train_only_the_features(backend):
    """With ``feature_geometry_grad=False`` the outputs are unchanged, a loss on the features
    moves only ``obj_feat`` (by the same gradient as the fused render's), and a loss on the
    other outputs moves the geometry exactly as before."""
    cam, pose = look_down_z(40, 32)
    g = random_gaussians(150, 4)
    weights = output_weights(cam.width, cam.height, 4, torch.float32)
    split = {
        "features": {"features": weights["features"]},
        "rest": {k: w for k, w in weights.items() if k != "features"},
    }
    for part, w in split.items():
        grads = {}
        for coupled in (True, False):
            params = Gaussians(**{k: v.clone().requires_grad_(True) for k, v in g.tensors().items()})
            out = render(params, cam, pose, feature_geometry_grad=coupled, backend=backend)
            weighted_sum(out, w).backward()
            grads[coupled] = {k: torch.zeros_like(v) if v.grad is None else v.grad for k, v in params.tensors().items()}
            if coupled:
                fused = out
            else:
                for name in OUTPUTS:
                    torch.testing.assert_close(getattr(out, name), getattr(fused, name), atol=1e-6, rtol=0)
        for name, coupled_grad in grads[True].items():
            detached_grad = grads[False][name]
            if part == "features" and name in GEOMETRY:
                assert coupled_grad.abs().max() > 0 and detached_grad.abs().max() == 0, name
            else:
                torch.testing.assert_close(detached_grad, coupled_grad, atol=1e-5, rtol=1e-4)


@pytest.mark.parametrize("seed, size", [(5, (40, 32)), (6, (90, 70))])
def test_features_at_sampled_pixels_match_the_full_render(seed, size):
    """``feature_pixels`` (repeats and any order allowed) gives the full render's features at
    those pixels, and the gradient a loss on them sends to ``obj_feat`` is the same; colour,
    alpha, depth and the geometry's gradients do not change. On the cpu backend the features
    are blended at those pixels alone."""
    cam, pose = look_down_z(*size)
    g = random_gaussians(400, seed, scales=(0.005, 0.08))
    pixels = torch.randint(0, cam.width * cam.height, (300,), generator=torch.Generator().manual_seed(seed))
    pixels[-5:] = pixels[:5]  # repeats
    weights = output_weights(cam.width, cam.height, seed, torch.float32)
    feature_weights = torch.randn(len(pixels), g.obj_feat.shape[1], generator=torch.Generator().manual_seed(seed))
    results = {}
    for backend, at in (("torch", False), ("cpu", False), ("cpu", True)):
        params = Gaussians(**{k: v.clone().requires_grad_(True) for k, v in g.tensors().items()})
        out = render(
            params, cam, pose, feature_geometry_grad=False, feature_pixels=pixels if at else None, backend=backend
        )
        features = out.features if at else out.features.reshape(-1, out.features.shape[-1])[pixels]
        loss = (features * feature_weights).sum() + sum(
            (getattr(out, k) * weights[k]).sum() for k in ("rgb", "alpha", "depth")
        )
        loss.backward()
        results[backend, at] = out, features, {k: v.grad for k, v in params.tensors().items()}
    full, full_features, full_grads = results["cpu", False]
    _, ref_features, ref_grads = results["torch", False]
    out, features, grads = results["cpu", True]
    assert features.shape == (len(pixels), g.obj_feat.shape[1]) and full_features.abs().max() > 0
    torch.testing.assert_close(features, full_features, atol=1e-6, rtol=0)
    torch.testing.assert_close(features, ref_features, atol=1e-4, rtol=0)
    for name in ("rgb", "alpha", "depth"):
        assert torch.equal(getattr(out, name), getattr(full, name)), name
    for name, expected in full_grads.items():
        torch.testing.assert_close(grads[name], expected, atol=1e-6, rtol=1e-5)
        rel = (grads[name] - ref_grads[name]).norm() / ref_grads[name].norm()
        assert rel < 1e-3, (name, rel.item())


@pytest.mark.parametrize("seed", [0, 1])
def test_cpu_projection_matches_the_tensor_projection(seed):
    """The numba projection of Gaussians in front of, beside (past the Jacobian's clamp at
    1.3x the field of view) and behind the camera equals :func:`project_gaussians` in float64,
    and so do the gradients of a loss on the drawn Gaussians' outputs."""
    cam, pose = look_down_z(40, 32)
    g = random_gaussians(300, seed, torch.float64, scales=(0.005, 0.3))
    with torch.no_grad():
        g.means[:40, 0] *= 3.0  # beside the field of view
        g.means[40:60, 2] = -3.6 - torch.rand(20, dtype=torch.float64)  # behind the camera
    weights = {
        k: torch.randn(s, generator=torch.Generator().manual_seed(seed))
        for k, s in (("means2d", (300, 2)), ("conics", (300, 3)), ("depths", (300,)))
    }
    results = []
    for project, dtype in ((project_gaussians, torch.float64), (project_gaussians_cpu, torch.float32)):
        params = [x.detach().to(dtype).requires_grad_(True) for x in (g.means, g.quats, g.scales)]
        proj = project(*params, pose.to(dtype), cam, g.opacities.detach().to(dtype))
        drawn = (proj.radii > 0).to(dtype)
        loss = sum(
            (getattr(proj, k) * w.to(dtype)).sum(-1) if w.dim() > 1 else getattr(proj, k) * w.to(dtype)
            for k, w in weights.items()
        )
        loss = (loss * drawn).sum()
        loss.backward()
        results.append((proj, [p.grad.double() for p in params]))
    (ref, ref_grads), (out, grads) = results
    assert (ref.radii > 0).sum() > 150 and (ref.radii[40:60] == 0).all() and (ref.radii[:40] > 0).any()
    assert torch.equal(out.radii, ref.radii) or (out.radii - ref.radii).abs().max() <= 1
    for name in ("means2d", "conics", "depths"):
        torch.testing.assert_close(getattr(out, name).double(), getattr(ref, name), rtol=1e-5, atol=1e-5)
    for grad, ref_grad in zip(grads, ref_grads, strict=True):
        torch.testing.assert_close(grad, ref_grad, rtol=1e-4, atol=1e-4 * ref_grad.abs().max().item())


def test_cpu_exponential_matches_math_exp():
    """The kernels' polynomial exponential, over the range of powers they evaluate."""
    x = np.linspace(float(cpu_kernels.POWER_FLOOR), 0.0, 401).astype(np.float32)
    approx = np.array([cpu_kernels.exp_f32(v) for v in x], np.float64)
    exact = np.exp(x.astype(np.float64))
    assert np.abs(approx / exact - 1).max() < 3e-7


@pytest.mark.slow
def test_torch_reference_matches_finite_differences():
    cam, pose = look_down_z(12, 10)
    g = random_gaussians(6, 1, torch.float64)
    names = list(g.tensors())
    weights = output_weights(cam.width, cam.height, 1, torch.float64)

    def loss(*tensors):
        return weighted_sum(render(Gaussians(**dict(zip(names, tensors))), cam, pose, backend="torch"), weights)

    inputs = [v.clone().requires_grad_(True) for v in g.tensors().values()]
    assert torch.autograd.gradcheck(loss, inputs, eps=1e-6, atol=1e-5, rtol=1e-4)


@pytest.mark.parametrize("backend", ["cpu", "torch"])
def test_single_gaussian_known_answer(backend):
    """An isotropic Gaussian of std s at depth z facing the camera: its 2D covariance is
    (f s / z)^2 + 0.3 on the diagonal, and a pixel's alpha is o * exp(-d^2 / (2 var))."""
    f, s, z, o = 20.0, 0.1, 2.0, 0.7
    cam = PinholeCamera(16, 16, f, f, 8.0, 8.0)
    g = Gaussians(
        means=torch.tensor([[0.0, 0.0, z]]),
        log_scales=torch.full((1, 3), math.log(s)),
        quats=torch.tensor([[1.0, 0, 0, 0]]),
        opacity_logits=torch.logit(torch.tensor([o])),
        sh_dc=torch.zeros(1, 3),
        sh_rest=torch.zeros(1, 15, 3),
        obj_feat=torch.ones(1, 16),
    )
    out = render(g, cam, torch.eye(4)[:3], backend=backend)
    var = (f * s / z) ** 2 + 0.3
    yy, xx = torch.meshgrid(torch.arange(16) + 0.5, torch.arange(16) + 0.5, indexing="ij")
    alpha = o * torch.exp(-((xx - 8.0) ** 2 + (yy - 8.0) ** 2) / (2 * var))
    alpha = torch.where(alpha >= 1 / 255, alpha, torch.zeros_like(alpha))
    torch.testing.assert_close(out.alpha, alpha, atol=1e-6, rtol=1e-5)
    torch.testing.assert_close(out.rgb, 0.5 * alpha[..., None].expand(-1, -1, 3), atol=1e-6, rtol=1e-5)
    torch.testing.assert_close(out.depth, z * alpha, atol=1e-6, rtol=1e-5)
    torch.testing.assert_close(out.features, alpha[..., None].expand(-1, -1, 16), atol=1e-6, rtol=1e-5)


@pytest.mark.parametrize("backend", ["cpu", "torch"])
def test_gaussians_behind_the_camera_are_culled_with_zero_gradient(backend):
    cam, pose = look_down_z(16, 16)
    g = random_gaussians(20, 3)
    g.means[1:, 2] = -3.5 - torch.linspace(0, 1, 19)  # all but the first behind the camera, one on it
    g = Gaussians(**{k: v.requires_grad_(True) for k, v in g.tensors().items()})
    out = render(g, cam, pose, backend=backend)
    assert (out.radii[1:] == 0).all() and out.radii[0] > 0
    (out.rgb.sum() + out.alpha.sum()).backward()
    for name, value in g.tensors().items():
        assert torch.isfinite(value.grad).all() and value.grad[1:].abs().max() == 0, name


@pytest.mark.parametrize("backend", ["cpu", "torch"])
def test_the_cameras_near_plane_culls_nearer_gaussians(backend):
    g = Gaussians(
        means=torch.tensor([[0.0, 0.0, 0.5], [0.0, 0.0, 3.0]]),
        log_scales=torch.full((2, 3), math.log(0.05)),
        quats=torch.tensor([[1.0, 0, 0, 0]] * 2),
        opacity_logits=torch.zeros(2),
        sh_dc=torch.zeros(2, 3),
        sh_rest=torch.zeros(2, 15, 3),
        obj_feat=torch.ones(2, 16),
    )
    for near, drawn in ((0.2, [True, True]), (1.0, [False, True])):
        out = render(g, PinholeCamera(16, 16, 20.0, 20.0, 8.0, 8.0, near=near), torch.eye(4)[:3], backend=backend)
        assert (out.radii > 0).tolist() == drawn
    # with the near Gaussian culled, the image is the far one's alone
    alone = render(
        g.select(torch.tensor([False, True])),
        PinholeCamera(16, 16, 20.0, 20.0, 8.0, 8.0),
        torch.eye(4)[:3],
        backend=backend,
    )
    torch.testing.assert_close(out.alpha, alone.alpha)


def test_background_fills_what_the_gaussians_leave():
    cam, pose = look_down_z(24, 20)
    g = random_gaussians(30, 4)
    bg = torch.tensor([0.2, 0.4, 0.9])
    plain = render(g, cam, pose)
    over = render(g, cam, pose, background=bg)
    torch.testing.assert_close(over.rgb, plain.rgb + (1 - plain.alpha[..., None]) * bg)


def test_unknown_backend_is_refused():
    from dataset_tools.infra.errors import InputError

    with pytest.raises(InputError, match="unknown backend"):
        get_backend("opengl")
    assert get_backend("auto").name == ("gsplat" if BACKENDS["gsplat"].available() else "cpu")
    assert get_backend(get_backend("torch")) is BACKENDS["torch"]


@pytest.mark.skipif(not BACKENDS["gsplat"].available(), reason="the gsplat backend needs gsplat and a CUDA GPU")
@pytest.mark.parametrize("seed, n, size, scales", [(0, 150, (40, 32), (0.04, 0.24)), (3, 400, (90, 70), (0.005, 0.08))])
def test_gsplat_backend_matches_torch_reference(seed, n, size, scales):
    """To the tolerances of the cpu backend, on opacities below 0.99: gsplat clamps one
    Gaussian's alpha at 0.999 where 3D-GS (and ``cpu``, ``torch``) clamp at 0.99."""
    cam, pose = look_down_z(*size)
    g = random_gaussians(n, seed, scales=scales)
    g = Gaussians(**{**g.tensors(), "opacity_logits": g.opacity_logits.clamp(max=math.log(0.985 / 0.015))})
    weights = output_weights(cam.width, cam.height, seed, torch.float32)
    ref, ref_grads = _render_with_grads(g, "torch", weights, cam, pose)
    cuda = Gaussians(**{k: v.cuda() for k, v in g.tensors().items()})
    out, grads = _render_with_grads(cuda, "gsplat", {k: w.cuda() for k, w in weights.items()}, cam, pose.cuda())
    for name in OUTPUTS:
        torch.testing.assert_close(getattr(out, name).cpu(), getattr(ref, name), atol=1e-4, rtol=0)
    for name, expected in ref_grads.items():
        rel = (grads[name].cpu() - expected).norm() / expected.norm()
        assert expected.norm() > 0 and rel < 1e-3, (name, rel.item())


def test_a_pose_or_background_of_the_wrong_shape_is_refused_naming_it():
    cam, pose = look_down_z(8, 8)
    g = random_gaussians(3, 0)
    with pytest.raises(ValueError, match=r"cam_from_world has shape \(3, 3\)"):
        render(g, cam, pose[:3, :3])
    with pytest.raises(ValueError, match=r"background has shape \(4,\)"):
        render(g, cam, pose, background=torch.zeros(4))
