"""The learned environment behind the Gaussians: ray directions, SH colour, the elevation
profile and its up direction, compositing, training and the run folder."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from helpers import numba_threads

from dataset_tools.cameras import PinholeCamera
from dataset_tools.infra.errors import InputError
from dataset_tools.synth.camera_paths import look_at, orbit
from gsseg.model.environment import Environment, background_image, mean_up, profile_bins, ray_directions
from gsseg.model.gaussians import Gaussians
from gsseg.model.sh import C0, C1
from gsseg.render import render

CAMERA = PinholeCamera(width=8, height=6, fx=10.0, fy=10.0, cx=4.0, cy=3.0)


def rotation_z(deg: float) -> np.ndarray:
    a = np.deg2rad(deg)
    return np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])


def test_ray_directions_are_the_world_rays_through_pixel_centres():
    R = rotation_z(30.0) @ np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # any rotation
    pose = torch.as_tensor(np.concatenate([R, [[1.0], [2.0], [3.0]]], 1), dtype=torch.float32)
    dirs = ray_directions(CAMERA, pose)
    assert dirs.shape == (6, 8, 3) and torch.allclose(dirs.norm(dim=-1), torch.ones(6, 8))
    # Pixel (row 2, column 3) is centred at (3.5, 2.5): camera ray (-0.05, -0.05, 1).
    d_cam = np.array([-0.05, -0.05, 1.0]) / np.linalg.norm([-0.05, -0.05, 1.0])
    assert dirs[2, 3].numpy() == pytest.approx(R.T @ d_cam, abs=1e-6)


def test_environment_colour_follows_its_sh_coefficients():
    env = Environment(degree=1)
    with torch.no_grad():
        env.coeffs[0, 0] = torch.tensor([0.4, 0.0, -0.4]) / C0  # grey 0.5 +-0.4
        env.coeffs[0, 2, 1] = 0.3 / C1  # green follows the world z of the ray
    pose = torch.eye(4)[:3]  # camera looking along world +z
    image = env(CAMERA, pose)
    z = ray_directions(CAMERA, pose)[..., 2]
    assert torch.allclose(image[..., 0], torch.full_like(z, 0.9), atol=1e-6)
    assert torch.allclose(image[..., 1], 0.5 + 0.3 * z, atol=1e-6)
    assert torch.allclose(image[..., 2], torch.full_like(z, 0.1), atol=1e-6)
    assert background_image(None, CAMERA, pose) is None


def test_mean_up_is_the_world_up_of_an_orbit_looking_down():
    poses = orbit(24, 4.0, np.zeros(3))  # every camera pitched 18-34 degrees down
    assert mean_up(poses) == pytest.approx([0.0, 0.0, 1.0], abs=1e-9)
    flipped = [np.diag([-1.0, -1.0, 1.0]) @ p for p in poses[:2]]  # rolled upside down
    with pytest.raises(InputError, match="environment_profile=False"):
        mean_up(poses[:2] + flipped)


def test_elevation_profile_is_linear_between_bin_centres():
    """Four bins over [-90, 90] degrees have centres at -67.5, -22.5, 22.5 and 67.5: a ray at
    0 degrees takes the mean of the middle two, one beyond the outer centres the outer bin."""
    env = Environment(degree=0, up=np.array([0.0, 0.0, 1.0]), bins=4)
    with torch.no_grad():
        env.profile.copy_(torch.tensor([[0.0] * 3, [0.2] * 3, [0.6] * 3, [1.0] * 3]))
    elevations = torch.deg2rad(torch.tensor([0.0, 22.5, 45.0, -45.0, 80.0, -89.0]))
    dirs = torch.stack([torch.cos(elevations), torch.zeros_like(elevations), torch.sin(elevations)], -1)
    expected = torch.tensor([0.4, 0.6, 0.8, 0.1, 1.0, 0.0])
    assert torch.allclose(env.elevation_colour(dirs), expected[:, None].expand(-1, 3), atol=1e-6)
    assert profile_bins(1.0 / np.tan(np.pi / 180)) == 180  # one-degree pixels


def test_profile_gradient_is_the_in_order_sum_of_its_pixels():
    """Each bin's gradient is the float32 sum of its rays' gradients taken in ray order (as
    ``np.add.at`` takes them), the same bits however the threads are scheduled."""
    bins = 16
    env = Environment(degree=0, up=np.array([0.0, 0.0, 1.0]), bins=bins)
    gen = torch.Generator().manual_seed(0)
    dirs = torch.nn.functional.normalize(torch.randn(20_000, 3, generator=gen), dim=-1)
    grad = torch.randn(20_000, 3, generator=gen)
    env.elevation_colour(dirs).backward(grad)
    x = (torch.asin((dirs @ env.up).clamp(-1.0, 1.0)) / np.pi + 0.5) * bins - 0.5
    lo = x.floor().clamp(0, bins - 1)
    w = (x - lo).clamp(0.0, 1.0)[:, None]
    lo = lo.long().numpy()
    lower, upper = np.zeros((bins, 3), np.float32), np.zeros((bins, 3), np.float32)
    np.add.at(lower, lo, ((1 - w) * grad).numpy())
    np.add.at(upper, np.minimum(lo + 1, bins - 1), (w * grad).numpy())
    assert np.array_equal(env.profile.grad.numpy(), lower + upper)


@pytest.mark.parametrize("degree, bins", [(3, 40), (1, 0), (3, 0)])
def test_cpu_kernels_match_the_tensor_image_and_gradients(degree, bins):
    """The numba image of a rotated camera with random coefficients and profile (some colours
    clamped at 0) equals :meth:`Environment.image_torch`, and so do the gradients of a loss on
    it; the gradients have the same bits on one thread as on two."""
    camera = PinholeCamera(width=37, height=29, fx=30.0, fy=31.0, cx=17.0, cy=15.5)
    pose = torch.as_tensor(look_at(np.array([0.3, -2.0, 0.5]), np.zeros(3)), dtype=torch.float32)
    env = Environment(degree, up=np.array([0.1, 0.2, 0.97]) / np.linalg.norm([0.1, 0.2, 0.97]), bins=bins)
    gen = torch.Generator().manual_seed(degree + bins)
    with torch.no_grad():
        env.coeffs.copy_(1.5 * torch.randn(env.coeffs.shape, generator=gen))
        if bins:
            env.profile.copy_(torch.randn(env.profile.shape, generator=gen))
    weights = torch.randn(camera.height, camera.width, 3, generator=gen)
    results = []
    for image_of, threads in ((env.image_torch, 2), (env, 2), (env, 1)):
        env.zero_grad()
        with numba_threads(threads):
            image = image_of(camera, pose)
            (image * weights).sum().backward()
        results.append((image.detach(), [p.grad.clone() for p in env.parameters()]))
    (ref, ref_grads), (image, grads), (_, one_thread_grads) = results
    assert image.shape == (29, 37, 3) and (bins > 0 or (ref == 0).any())
    torch.testing.assert_close(image, ref, atol=2e-5, rtol=0)
    for grad, ref_grad, one in zip(grads, ref_grads, one_thread_grads, strict=True):
        torch.testing.assert_close(grad, ref_grad, atol=1e-4, rtol=1e-5)
        assert torch.equal(grad, one)


@pytest.mark.slow
def test_a_sharp_horizon_is_learned_by_the_profile_and_not_by_sh_alone():
    """An environment that is the sky's gradient above the horizon and a flat ground colour
    below it, fitted from four views around it: with the profile the mean squared error is
    under 1e-4 (what is left is the one-bin blur at the step); degree-3 SH alone blurs the
    step into an error 50 times larger."""
    camera = PinholeCamera(width=24, height=24, fx=26.0, fy=26.0, cx=12.0, cy=12.0)
    poses = [
        torch.as_tensor(look_at(np.zeros(3), np.array([np.cos(a), np.sin(a), -0.1])), dtype=torch.float32)
        for a in np.linspace(0, 2 * np.pi, 4, endpoint=False)
    ]

    def truth(pose):
        z = ray_directions(camera, pose)[..., 2:3]
        return torch.where(z > 0, 0.8 - 0.5 * z, torch.tensor([0.5, 0.45, 0.4]))

    errors = {}
    for bins in (0, profile_bins(camera.fx)):
        env = Environment(degree=3, up=np.array([0.0, 0.0, 1.0]), bins=bins)
        adam = torch.optim.Adam(env.parameters(), lr=0.02)
        for _ in range(300):
            loss = sum(((env(camera, p) - truth(p)) ** 2).mean() for p in poses)
            adam.zero_grad()
            loss.backward()
            adam.step()
        with torch.no_grad():
            errors[bins > 0] = max(float(((env(camera, p) - truth(p)) ** 2).mean()) for p in poses)
    assert errors[True] < 1e-4 and errors[False] > 50 * errors[True]


def test_environment_state_round_trip_with_and_without_profile():
    pose = torch.as_tensor(look_at(np.zeros(3), np.array([1.0, 0.0, 0.2])), dtype=torch.float32)
    for env in (Environment(degree=2), Environment(degree=1, up=np.array([0.0, 0.0, 1.0]), bins=7)):
        for p in env.parameters():
            torch.nn.init.normal_(p, generator=torch.Generator().manual_seed(0))
        copy = Environment.from_state(env.state_dict())
        assert copy.degree == env.degree and (copy.profile is None) == (env.profile is None)
        assert torch.equal(copy(CAMERA, pose), env(CAMERA, pose))


def test_render_composites_an_image_background_behind_the_gaussians():
    g = Gaussians(
        means=torch.tensor([[0.0, 0.0, 2.0]]),
        log_scales=torch.full((1, 3), -2.0),
        quats=torch.tensor([[1.0, 0, 0, 0]]),
        opacity_logits=torch.tensor([2.0]),
        sh_dc=torch.zeros(1, 3),
        sh_rest=torch.zeros(1, 15, 3),
        obj_feat=torch.zeros(1, 16),
    )
    pose = torch.eye(4)[:3]
    background = torch.rand(6, 8, 3, generator=torch.Generator().manual_seed(0))
    plain = render(g, CAMERA, pose, with_features=False)
    over = render(g, CAMERA, pose, background=background, with_features=False)
    assert torch.allclose(over.rgb, plain.rgb + (1 - plain.alpha[..., None]) * background, atol=1e-6)
    assert plain.alpha.max() > 0.5 and plain.alpha.min() < 0.01  # both cases occur


def test_environment_is_learned_through_the_composite():
    """Fitting a render whose only Gaussian covers part of the view to a sky that brightens
    upwards recovers that sky in the environment: the gradient reaches it through (1 - alpha)."""
    g = Gaussians(
        means=torch.tensor([[0.0, 0.0, 2.0]]),
        log_scales=torch.full((1, 3), -2.0),
        quats=torch.tensor([[1.0, 0, 0, 0]]),
        opacity_logits=torch.tensor([4.0]),
        sh_dc=torch.zeros(1, 3),
        sh_rest=torch.zeros(1, 15, 3),
        obj_feat=torch.zeros(1, 16),
    )
    pose = torch.as_tensor([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0]])  # looking along world +y
    sky = 0.5 + 0.4 * ray_directions(CAMERA, pose)[..., 2:3].expand(-1, -1, 3)
    target = render(g, CAMERA, pose, background=sky, with_features=False).rgb
    env = Environment(degree=1)
    adam = torch.optim.Adam(env.parameters(), lr=0.05)
    for _ in range(300):
        loss = ((render(g, CAMERA, pose, background=env(CAMERA, pose), with_features=False).rgb - target) ** 2).mean()
        adam.zero_grad()
        loss.backward()
        adam.step()
    assert torch.allclose(env(CAMERA, pose), sky, atol=0.02)


def test_runs_carry_their_environment_to_the_renderers(small_scene, trained, tmp_path):
    from dataset_tools import load_scene
    from dataset_tools.image_files import read_image
    from gsseg.render import to_uint8
    from gsseg.render.views import render_run
    from gsseg.run.loaded import load_run

    run = load_run(trained)
    assert run.environment is not None and run.environment.degree == 3 and run.environment.profile is not None
    out = render_run(trained, small_scene.root, tmp_path / "r", what=("rgb",), backend="cpu", progress=False)
    view = load_scene(small_scene.root).split("test")[0]
    pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32)
    with torch.no_grad():
        expected = render(
            run.gaussians,
            view.camera,
            pose,
            with_features=False,
            background=background_image(run.environment, view.camera, pose),
        ).rgb
        black = render(run.gaussians, view.camera, pose, with_features=False).rgb
    written = read_image(out / "rgb" / f"{view.stem}.png")
    assert np.array_equal(written, to_uint8(expected)) and not np.array_equal(written, to_uint8(black))
