"""What is optimised: Gaussians, the camera trajectory, contrast thresholds and exposure gains."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.camera.trajectory import Trajectory
from fusiongs.losses.threshold import ContrastThreshold
from fusiongs.render import rasterize
from fusiongs.render.rasterize import RenderMeta
from fusiongs.scene.gaussians import GaussianModel
from fusiongs.train.data import TrainData
from fusiongs.train.settings import DeblurConfig


class FusionState(nn.Module):
    """The optimised state of one scene.

    Attributes:
        model: the Gaussians; their colour is linear radiance (SH, gsplat's ``+0.5`` convention).
        trajectory: camera-to-world poses in time, with learnable knot corrections.
        threshold: contrast thresholds θ = exp(s) per polarity (and per colour channel).
        log_gain: ``[F]`` log exposure gains g_i (zeros; learnable when configured).
    """

    def __init__(self, model: GaussianModel, trajectory: Trajectory, threshold: ContrastThreshold,
                 n_frames: int, learn_gain: bool):
        super().__init__()
        self.model = model
        self.trajectory = trajectory
        self.threshold = threshold
        self.log_gain = nn.Parameter(torch.zeros(n_frames), requires_grad=learn_gain)

    def render(self, camera: PinholeCamera, t: torch.Tensor, backend: str = "auto"
               ) -> tuple[torch.Tensor, torch.Tensor, RenderMeta]:
        """Sharp linear renders at instants ``t`` ``[T]`` (s): ``([T, H, W, 3], alphas, meta)``."""
        m = self.model
        device = m.means.device
        viewmats = self.trajectory.w2c(t.to(torch.float64)).to(device=device, dtype=m.means.dtype)
        Ks = camera.K(dtype=m.means.dtype, device=device).expand(viewmats.shape[0], 3, 3)
        colors, alphas, meta = rasterize(m.means, m.rotations, m.scales, m.opacities, m.sh_coeffs(),
                                         viewmats, Ks, camera.width, camera.height,
                                         sh_degree=m.active_sh_degree, backend=backend)
        return colors, alphas, meta


def scene_extent(c2w: np.ndarray, depth_max: float) -> float:
    """Scene scale for learning rates and densification: camera path radius plus the far depth."""
    centres = c2w[:, :3, 3]
    radius = float(np.linalg.norm(centres - centres.mean(0), axis=1).max()) if len(centres) else 0.0
    return 1.1 * (radius + depth_max)


def build_state(data: TrainData, poses_c2w: np.ndarray, trajectory: Trajectory, cfg: DeblurConfig,
                device: torch.device, theta_init: float | None = None) -> FusionState:
    """Initial state: random Gaussians in the frusta of the cameras at the frame times.

    Args:
        theta_init: starting contrast threshold; ``cfg.threshold.init`` when None.
    """
    theta_init = cfg.threshold.init if theta_init is None else theta_init
    gen = torch.Generator().manual_seed(cfg.seed)
    if data.n_frames:
        t_init = data.exposures.mean(dim=1)
    else:
        t_init = torch.linspace(data.t_range[0], data.t_range[1], 16, dtype=torch.float64)
    with torch.no_grad():
        c2w = trajectory.c2w(t_init).to(torch.float32)
    model = GaussianModel.random_in_frusta(data.camera, c2w, cfg.init.n_points, cfg.init.depth_min,
                                           cfg.init.depth_max, generator=gen,
                                           sh_degree=cfg.init.sh_degree, init_opacity=cfg.init.opacity,
                                           depth_sampling=cfg.init.depth_sampling)
    channels = 3 if data.cfa_index is not None else 1
    th = cfg.threshold
    threshold = ContrastThreshold(channels=channels, init=theta_init, grid=th.grid,
                                  image_size=(data.camera.height, data.camera.width),
                                  time_knots=th.time_knots, time_range=data.t_range)
    return FusionState(model, trajectory, threshold, data.n_frames, cfg.blur.learn_gain).to(device)
