"""What is optimised: Gaussians, the camera trajectory, contrast thresholds and exposure gains."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from fusiongs.camera.lie import rigid_inverse
from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.camera.trajectory import Trajectory
from fusiongs.losses.threshold import ContrastThreshold
from fusiongs.render import rasterize
from fusiongs.render.rasterize import RenderMeta
from fusiongs.scene.gaussians import GaussianModel
from fusiongs.train.data import TrainData, block_mean, coarse_camera
from fusiongs.train.settings import DeblurConfig


class FusionState(nn.Module):
    """The optimised state of one scene.

    Attributes:
        model: the Gaussians; their colour is linear radiance (SH, gsplat's ``+0.5`` convention).
        trajectory: camera-to-world poses in time, with learnable knot corrections. Built on the
            host (:func:`~fusiongs.train.trainer.build_trajectory`) whatever the device of the
            Gaussians: a render's poses are a few dozen 4x4 matrices through some 400 small ops
            (SE(3) log and exp of the B-spline) and as many backward nodes, which on a GPU are
            that many kernel launches for a kilobyte of arithmetic, a third of a training step's
            launches; on the host they cost microseconds each, and only
            the ``[T, 4, 4]`` view matrices cross to the device (their gradient back).
        threshold: contrast thresholds θ = exp(s) per polarity (and per colour channel).
        log_gain: ``[F]`` log exposure gains g_i (zeros; learnable when configured).
        depth_far: far bound of the initialisation (scene units; sizes the scene extent).
    """

    def __init__(self, model: GaussianModel, trajectory: Trajectory, threshold: ContrastThreshold,
                 n_frames: int, learn_gain: bool, depth_far: float = 12.0):
        super().__init__()
        self.depth_far = float(depth_far)
        self.model = model
        self.trajectory = trajectory
        self.threshold = threshold
        self.log_gain = nn.Parameter(torch.zeros(n_frames, device=model.means.device),
                                     requires_grad=learn_gain)

    def _views(self, camera: PinholeCamera, t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(viewmats [T, 4, 4], Ks [T, 3, 3])`` at instants ``t`` on the Gaussians' device and dtype."""
        # the view matrices are made where the trajectory lives and copied without waiting
        return self._on_device(camera, self.trajectory.w2c(t.to(torch.float64)))

    def _on_device(self, camera: PinholeCamera, w2c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(viewmats, Ks)`` of world-to-camera matrices ``w2c`` ``[T, 4, 4]``, copied without
        waiting to the Gaussians' device and dtype."""
        m = self.model
        device = m.means.device
        viewmats = w2c.to(device, m.means.dtype, non_blocking=True)
        # K is made on the host and copied without waiting (torch.tensor(..., device=cuda) waits)
        K = camera.K(dtype=m.means.dtype, device="cpu").to(device, non_blocking=True)
        return viewmats, K.expand(viewmats.shape[0], 3, 3)

    def render(self, camera: PinholeCamera, t: torch.Tensor, backend: str = "auto",
               check_values: bool = True) -> tuple[torch.Tensor, torch.Tensor, RenderMeta]:
        """Sharp linear renders at instants ``t`` ``[T]`` (s): ``([T, H, W, 3], alphas, meta)``.

        ``t`` should be on the trajectory's device (the host, see the class docstring; a ``t`` on
        another device is copied there, which waits for it); ``check_values=False`` skips the
        rasteriser's value checks (host syncs on a GPU).
        """
        return self._rasterize(camera, *self._views(camera, t), backend, check_values)

    def render_poses(self, camera: PinholeCamera, c2w: torch.Tensor, backend: str = "auto"
                     ) -> tuple[torch.Tensor, torch.Tensor, RenderMeta]:
        """Sharp linear renders from given camera poses, not the fitted path (novel views).

        Args:
            camera: the intrinsics.
            c2w: ``[T, 4, 4]`` camera-to-world rigid transforms in the run's world frame (that of
                its refined ``trajectory.txt``; OpenCV axes), any device and float dtype.

        Returns:
            ``([T, H, W, 3] linear colours, alphas, meta)`` as :meth:`render`.
        """
        return self._rasterize(camera, *self._pose_views(camera, c2w), backend, True)

    def _pose_views(self, camera: PinholeCamera, c2w: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(viewmats, Ks)`` of camera-to-world poses ``[T, 4, 4]``, inverted on the host in float64
        (as the trajectory's are) and copied to the Gaussians' device."""
        return self._on_device(camera, rigid_inverse(c2w.detach().to("cpu", torch.float64)))

    def _rasterize(self, camera: PinholeCamera, viewmats: torch.Tensor, Ks: torch.Tensor, backend: str,
                   check_values: bool) -> tuple[torch.Tensor, torch.Tensor, RenderMeta]:
        m = self.model
        return rasterize(m.means, m.rotations, m.scales, m.opacities, m.sh_coeffs(), viewmats, Ks,
                         camera.width, camera.height, sh_degree=m.active_sh_degree, backend=backend,
                         check_values=check_values)

    @torch.no_grad()
    def render_depth(self, camera: PinholeCamera, t: torch.Tensor, backend: str = "auto"
                     ) -> tuple[torch.Tensor, torch.Tensor]:
        """Expected surface depth at instants ``t`` ``[T]``: ``(depth [T, H, W], alpha [T, H, W])``.

        Each Gaussian is rendered with its centre's camera depth as a one-channel colour; the
        composite divided by the accumulated opacity is the depth along the optical axis (scene
        units) where ``alpha`` is near 1, undefined where nothing was rendered.
        """
        return self._depth(camera, *self._views(camera, t), backend)

    @torch.no_grad()
    def render_depth_poses(self, camera: PinholeCamera, c2w: torch.Tensor, backend: str = "auto"
                           ) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`render_depth` from camera-to-world poses ``[T, 4, 4]`` (as :meth:`render_poses`)."""
        return self._depth(camera, *self._pose_views(camera, c2w), backend)

    def _depth(self, camera: PinholeCamera, viewmats: torch.Tensor, Ks: torch.Tensor, backend: str
               ) -> tuple[torch.Tensor, torch.Tensor]:
        m = self.model
        z = (m.means @ viewmats[:, :3, :3].transpose(1, 2) + viewmats[:, None, :3, 3])[..., 2:]  # [T, N, 1]
        comp, alphas, _ = rasterize(m.means, m.rotations, m.scales, m.opacities, z, viewmats, Ks,
                                    camera.width, camera.height, backend=backend)
        alpha = alphas[..., 0]
        return comp[..., 0] / alpha.clamp_min(1e-6), alpha


def scene_extent(c2w: np.ndarray, depth_max: float) -> float:
    """Scene scale for learning rates and densification: camera path radius plus the far depth."""
    centres = c2w[:, :3, 3]
    radius = float(np.linalg.norm(centres - centres.mean(0), axis=1).max()) if len(centres) else 0.0
    return 1.1 * (radius + depth_max)


EVENT_ONLY_VIEWS = 16  # without frames: the instants the first Gaussians are posed (and matched) at
STEREO_FAR_FACTOR = 1000.0  # the far-bound sweep of init.far_from_stereo reaches this x depth_min


def stereo_factor(width: int, max_width: int) -> int:
    """The least integer block size that brings ``width`` to at most ``max_width`` (1 when it is
    already there, or when ``max_width`` is 0)."""
    return 1 if max_width <= 0 or width <= max_width else -(-int(width) // int(max_width))


def initial_gaussians(data: TrainData, c2w: torch.Tensor, cfg: DeblurConfig, gen: torch.Generator,
                      images: torch.Tensor | None = None, fill: torch.Tensor | None = None
                      ) -> tuple[GaussianModel, float]:
    """The initial Gaussians (``cfg.init``): random in the frusta, or stereo points plus random ones.

    Points are drawn on ``gen``'s device and returned on ``c2w``'s (the trainer's ``gen`` is on
    the CPU so that a run starts from the same Gaussians on every device).

    ``init.method = "auto"`` is ``"stereo"`` with two or more images, else ``"random"``.
    ``"stereo"`` plane-sweeps ``images`` (``[F, H, W, C]`` linear, e.g. EDI frames, posed by ``c2w``
    ``[F, 4, 4]``; :func:`fusiongs.camera.stereo.stereo_points`), keeps at most
    ``stereo_share · n_points`` of the confident surface points, drawn uniformly, coloured by their
    pixel, and fills the rest of ``n_points`` with random points of colour ``fill`` (``[3]`` linear,
    grey 0.5 when None: untextured or unseen parts).
    With ``init.far_from_stereo`` a first sweep reaches ``STEREO_FAR_FACTOR · depth_min`` (planes
    are uniform in inverse depth, so this costs little resolution near the camera) and the far
    bound becomes :func:`fusiongs.camera.stereo.far_bound` of its points, at least ``depth_max``.
    When the bound moved, that sweep's points up to it are kept and the random ones fill the
    frusta out to it; when it did not, the points come from a second sweep of
    ``[depth_min, depth_max]`` (finer planes; the same Gaussians as without the option).

    Returns:
        ``(model, far)``: the Gaussians and the far bound used (scene units; ``depth_max`` unless
        raised by the stereo points), which also sizes the scene extent (:func:`scene_extent`).

    Raises:
        ConfigError: ``stereo`` without at least two images, or with ``init.depth_min <= 0``.
    """
    from fusiongs.camera.frusta import sample_in_frusta
    from fusiongs.camera.stereo import far_bound, nearest_camera_distance, stereo_points
    from fusiongs.errors import ConfigError

    ini = cfg.init
    n_images = 0 if images is None else images.shape[0]
    if ini.method == "random" or (ini.method == "auto" and n_images < 2):
        return GaussianModel.random_in_frusta(data.camera, c2w, ini.n_points, ini.depth_min,
                                              ini.depth_max, generator=gen, sh_degree=ini.sh_degree,
                                              init_opacity=ini.opacity,
                                              depth_sampling=ini.depth_sampling), ini.depth_max
    if n_images < 2:
        raise ConfigError("config", "init.method", "'random' for a scene with fewer than 2 frames "
                          "(stereo initialisation matches frames)", repr(ini.method))
    if ini.depth_min <= 0:
        raise ConfigError("config", "init.depth_min", "a depth > 0 for the stereo initialisation "
                          "(its planes are uniform in 1/depth)", repr(ini.depth_min))
    camera, views = data.camera, images
    k = stereo_factor(camera.width, ini.stereo_max_width)
    if k > 1:  # the sweep's cost and memory grow with the pixels; the points it gives do not need them
        camera, views = coarse_camera(camera, k), block_mean(torch.as_tensor(images), k)

    def sweep(far: float) -> tuple[torch.Tensor, torch.Tensor]:
        xyz, rgb, _ = stereo_points(views, c2w, camera, ini.depth_min, far,
                                    n_planes=ini.stereo_planes, min_confidence=ini.stereo_min_confidence)
        return xyz, rgb

    far = ini.depth_max
    if ini.far_from_stereo:
        wide = max(STEREO_FAR_FACTOR * ini.depth_min, ini.depth_max)
        xyz, rgb = sweep(wide)
        dist = nearest_camera_distance(xyz, c2w[:, :3, 3].detach().cpu())
        far = far_bound(dist, ini.depth_max, wide)
        if far > ini.depth_max:  # a deep scene: the wide sweep's points, up to the far bound
            xyz, rgb = xyz[dist <= far], rgb[dist <= far]
        else:  # within depth_max: the finer sweep of [depth_min, depth_max], as without the option
            xyz, rgb = sweep(far)
    else:
        xyz, rgb = sweep(far)
    n_stereo = min(xyz.shape[0], round(ini.stereo_share * ini.n_points))
    pick = torch.randperm(xyz.shape[0], generator=gen, device=gen.device)[:n_stereo].to(xyz.device)
    rgb = rgb[pick].clamp(0.0, 1.0)
    if rgb.shape[1] == 1:
        rgb = rgb.expand(-1, 3)
    rand = sample_in_frusta(data.camera, c2w.cpu(), ini.n_points - n_stereo, ini.depth_min,
                            far, gen, ini.depth_sampling).float()
    xyz = torch.cat([xyz[pick], rand]).to(c2w.device)
    fill = rand.new_full((3,), 0.5) if fill is None else fill.detach().to(rand)
    rgb = torch.cat([rgb, fill.expand_as(rand)]).to(c2w.device)
    return GaussianModel.from_points(xyz, rgb, ini.sh_degree, init_opacity=ini.opacity,
                                     where="stereo init"), far


def event_stereo_start(data: TrainData, cfg: DeblurConfig) -> bool:
    """Whether the first Gaussians come from stereo on the events' high-pass images posed at
    :data:`EVENT_ONLY_VIEWS` instants over the recording: without frames, and with a single frame
    under ``init.method = "auto"`` (one frame cannot be matched against another; without this the
    start would be random points, which the frame alone then flattens into its own view)."""
    return data.n_frames == 0 or (data.n_frames == 1 and cfg.init.method == "auto"
                                  and data.events is not None and len(data.events) > 0)


def build_state(data: TrainData, poses_c2w: np.ndarray, trajectory: Trajectory, cfg: DeblurConfig,
                device: torch.device, theta_init=None, init_images: torch.Tensor | None = None,
                fill: torch.Tensor | None = None) -> FusionState:
    """Initial state: Gaussians from :func:`initial_gaussians` with the cameras at the frame times.

    Args:
        theta_init: starting contrast thresholds (a float, an ON/OFF pair or ``[2, C]``);
            ``cfg.threshold.init`` when None.
        init_images: ``[F, H, W, C]`` linear images for ``init.method = "stereo"``.
        fill: ``[3]`` linear colour of the random points (:func:`initial_gaussians`).
    """
    theta_init = cfg.threshold.init if theta_init is None else theta_init
    # on the host on purpose: the same initial Gaussians on every device (drawn points are moved
    # to the device by initial_gaussians)
    gen = torch.Generator(device="cpu").manual_seed(cfg.seed)
    if not event_stereo_start(data, cfg):
        t_init = data.exposures.mean(dim=1)
    else:
        t_init = torch.linspace(data.t_range[0], data.t_range[1], EVENT_ONLY_VIEWS, dtype=torch.float64,
                                device=trajectory.knots.device)
    with torch.no_grad():
        c2w = trajectory.c2w(t_init).to(torch.float32)
    model, far = initial_gaussians(data, c2w, cfg, gen, init_images, fill)
    channels = 3 if data.cfa_index is not None else 1
    init = np.asarray(theta_init, dtype=np.float64)
    if init.ndim == 2 and init.shape[1] != channels:  # per-channel values for a per-channel model only
        init = init.mean(axis=1, keepdims=True) if channels == 1 else np.repeat(init[:, :1], 3, axis=1)
    theta_init = init if init.ndim else float(init)
    th = cfg.threshold
    threshold = ContrastThreshold(channels=channels, init=theta_init, grid=th.grid,
                                  image_size=(data.camera.height, data.camera.width),
                                  time_knots=th.time_knots, time_range=data.t_range)
    # the trajectory stays where it was built (the host; see FusionState)
    return FusionState(model.to(device), trajectory, threshold.to(device), data.n_frames,
                       cfg.blur.learn_gain, depth_far=far)
