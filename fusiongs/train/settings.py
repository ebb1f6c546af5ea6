"""Settings of ``fusiongs deblur``: nested dataclasses loaded from ``configs/*.yaml``.

Field comments are the documentation of every key; defaults follow docs/method.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from fusiongs.errors import ConfigError


def _need_positive(section: str, obj: object, names: tuple[str, ...], zero_ok: bool = False) -> None:
    """ConfigError naming ``section.name`` for the first of ``names`` that is not a finite number
    > 0 (>= 0 with ``zero_ok``)."""
    for name in names:
        v = getattr(obj, name)
        if not (math.isfinite(v) and (v >= 0 if zero_ok else v > 0)):
            raise ConfigError("config", f"{section}.{name}",
                              "a finite number >= 0" if zero_ok else "a finite number > 0", repr(v))


@dataclass
class InitSettings:
    # stereo: plane sweep on the EDI frames (or the frames without events) plus random points;
    # auto: stereo on the frames with >= 2 frames; with events and fewer frames (none or one),
    # stereo on the events' high-pass images; random otherwise
    method: Literal["auto", "random", "stereo"] = "auto"
    n_points: int = 15000            # initial Gaussians (stereo points plus random ones in the frusta)
    depth_min: float = 1.0           # near bound of the sampled depths (scene units)
    depth_max: float = 12.0          # far bound of the sampled depths (scene units); with
                                     # far_from_stereo, the least far bound
    far_from_stereo: bool = True     # stereo init: sweep out to 1000 depth_min and raise the far
                                     # bound (random points, scene extent) to 1.25x the 90th
                                     # percentile of the stereo points' distances (deep scenes)
    depth_sampling: Literal["volume", "depth", "disparity"] = "depth"  # density of sampled depths
    opacity: float = 0.2             # initial opacity
    sh_degree: int = 0               # spherical-harmonics degree of the colours (0-3)
    stereo_share: float = 0.85       # at most this share of n_points from stereo (the rest random)
    stereo_planes: int = 48          # depth hypotheses of the plane sweep (uniform in 1/z)
    stereo_min_confidence: float = 0.3  # drop pixels whose cost curve is flatter than this
    stereo_max_width: int = 400      # frames wider than this are block-averaged by the least integer
                                     # factor that brings them under it before the sweep (0: never)
    # colour of the first Gaussians of a one-frame scene started from the events' stereo: the
    # frame's mean linear colour (the HPF points around it), with the colour learning rates scaled
    # by its mean level / 0.5 so that a step changes log intensity as much as from grey; or grey
    # (0.5 linear); auto: the frame's for grey events (which carry no colour),
    # grey for colour events (the frame's start cost the dark RGGB scenes 1.5-3 dB). Chosen on
    # one-frame tuning seeds 7, 3, 8, 6, 5, 17
    start_colour: Literal["auto", "frame", "grey"] = "auto"

    def __post_init__(self) -> None:
        if not 0 <= self.stereo_share <= 1:
            raise ConfigError("config", "init.stereo_share", "a number in [0, 1]", repr(self.stereo_share))
        if self.stereo_planes < 2:
            raise ConfigError("config", "init.stereo_planes", "an integer >= 2", repr(self.stereo_planes))
        if self.stereo_max_width < 0:
            raise ConfigError("config", "init.stereo_max_width", "0 (full resolution) or a width in "
                              "pixels", repr(self.stereo_max_width))
        if not 0 <= self.stereo_min_confidence < 1:
            raise ConfigError("config", "init.stereo_min_confidence", "a number in [0, 1)",
                              repr(self.stereo_min_confidence))


@dataclass
class BlurSettings:
    n_samples: int = 9               # N sharp renders inside each exposure (odd: middle = mid-exposure);
                                     # the most N when blur.sample_spacing > 0
    ssim_lambda: float = 0.2         # λ in (1-λ)·L1 + λ·(1-SSIM)
    weight: float = 1.0              # weight of the blur loss
    learn_gain: bool = False         # learnable per-frame exposure gain g_i
    coarse_until: int = 1000         # before this iteration, and only while λ_ev = 0, render at
    coarse_factor: int = 2           # 1/coarse_factor resolution against area-downsampled frames
    coarse_n_samples: int | None = 5  # N of the coarse steps (None: n_samples); blur trails are
                                     # coarse_factor times shorter in coarse pixels
    crop: tuple[int, int] | None = None  # (w, h): render a random crop per step; None = whole frame
    sample_spacing: float = 1.0      # px: N is the fewest odd count >= 5 (at most n_samples) whose
                                     # renders move at most this far apart in 90 % of the
                                     # exposures (train/exposure_samples.py); the run's
                                     # config.yaml holds the N used and 0 here; 0: N = n_samples

    def __post_init__(self) -> None:
        for name in ("n_samples", "coarse_factor", "coarse_n_samples"):
            v = getattr(self, name)
            if v is not None and v < 1:
                raise ConfigError("config", f"blur.{name}", "an integer >= 1", repr(v))
        _need_positive("blur", self, ("sample_spacing",), zero_ok=True)
        if self.crop is not None and min(self.crop) < 16:
            raise ConfigError("config", "blur.crop", "null or [w, h] with w, h >= 16 pixels",
                              repr(self.crop))


@dataclass
class EventSettings:
    enabled: bool = True             # use the event loss at all
    loss: Literal["mse", "band", "pvc"] = "mse"
    beta: float = 0.0                # tolerance of the band loss (count units): 0 synthetic, 0.5 real
    weight: float = 0.1              # λ_ev after the warm-up
    warmup: int = 1000               # iterations with λ_ev = 0 and θ frozen
    ramp: int = 0                    # iterations of linear ramp of λ_ev after the warm-up
    pixels: int = 8192               # P sampled pixels per window
    frac_with_events: float = 0.9    # share of sampled pixels that saw events in the window
    windows_inside: int = 1          # windows between pairs of the N in-exposure instants
    windows_free: int = 1            # windows of log-uniform length anywhere in the stream
    chain_windows: bool = False      # free windows in a chain, each one's end the next one's
                                     # start: n windows in n + 1 renders instead of 2 n (event-only
                                     # 173x130: 10 % less training, −0.40 dB)
    min_window: float = 0.001        # shortest free window (s)
    max_window: float = 0.0          # longest free window (s); 0 = one frame interval (without
                                     # frames: the whole recording)
    window_events: float = 0.0       # ... and at most the time an average pixel takes to fire this
                                     # many events (0 = no such cap; train/step.py)
    colour_mode: Literal["mask", "demosaic"] = "mask"
    channel_weights: tuple[float, float, float] = (0.4, 0.2, 0.4)
    grey_weights: tuple[float, float, float] = (0.299, 0.587, 0.114)
    log_eps: float = 1e-3            # ε in log(I + ε), in units of the linear radiance range
    hpf_tau: float = 0.05            # τ of the high-pass filter for the pvc target (s)
    censor: float = 2.0              # counts of pixels with two events closer than this multiple of
                                     # the estimated dead time are lower bounds (one-sided mse); 0 off
    censor_radius: int = 0           # ... and those of their neighbours within this many pixels
    reset_weights: bool = True       # where the calibration found a pixel held in reset (its
                                     # pixel_model "reset"), each event counts the crossings it
                                     # stands for, as the calibration counted them (event loss,
                                     # and the EDI images of the prior and the initialisation)
    lowpass_weight: float = 0.0      # weight of the low-pass term on long windows between the free
                                     # windows' ends (train/lowpass_term.py; scenes without frames,
                                     # where nothing else fixes large scales); 0 off
    lowpass_sigma: float = 4.0       # its Gaussian (pixels)
    lowpass_history: int = 0         # ... also between this step's ends and those of the last
                                     # this many steps (kept log images; no extra render)

    def __post_init__(self) -> None:
        _need_positive("events", self, ("censor", "max_window", "window_events", "lowpass_weight"),
                       zero_ok=True)
        _need_positive("events", self, ("lowpass_sigma",))
        if self.chain_windows and self.loss == "pvc":  # pvc targets exist at read-outs only
            raise ConfigError("config", "events.chain_windows", "false with events.loss pvc", "true")
        for name in ("censor_radius", "lowpass_history"):  # integers: the config loader checks
            if getattr(self, name) < 0:
                raise ConfigError("config", f"events.{name}", "an integer >= 0", repr(getattr(self, name)))


@dataclass
class ThresholdSettings:
    init: float = 0.22               # initial θ for both polarities (when not estimated)
    estimate: bool = True            # start from the EDI consecutive-frame estimate (needs >= 2 frames)
    learn: bool = True               # learn θ after the warm-up
    lr: float = 1e-4                 # Adam lr of log θ; larger rates drift below the truth (RESULTS.md)
    regularise: float = 0.0          # weight of the pull toward the initial θ (scenes without frames only)
    grid: tuple[int, int] | None = None  # (gh, gw) spatial θ field over the sensor; None = scalar
    time_knots: int = 0              # knots of a slow θ drift over the recording (0 = none, else >= 2)
    smoothness: float = 1.0          # weight of the field / drift smoothness regulariser
    # when the events start (iteration events.warmup, >= 2 frames): raise each θ to the one the
    # renders fit to the counts, which reads low, not high (train/render_threshold.py). It mends
    # calibrations far below the truth (chosen on tuning seeds)
    render_floor: bool = True
    render_floor_windows: int = 32   # event windows of that fit (lengths up to one frame interval)
    render_floor_sigma: float = 3.0  # low-pass (pixels) of renders and counts in that fit; 0 none

    def __post_init__(self) -> None:
        if self.render_floor_windows < 1:
            raise ConfigError("config", "threshold.render_floor_windows", "an integer >= 1",
                              repr(self.render_floor_windows))
        _need_positive("threshold", self, ("init", "lr"))  # to freeze θ: threshold.learn=false
        _need_positive("threshold", self, ("regularise", "smoothness", "render_floor_sigma"), zero_ok=True)


@dataclass
class PriorSettings:
    edi_weight: float = 0.0          # weight of L1(mid-exposure render, EDI image) (DiET-GS-style prior)
    edi_until: int = 0               # iterations the EDI prior is on (weight decays linearly to 0)
    edi_theta: float = 0.0           # θ of the EDI images; 0 = the calibration (ON/OFF per channel)


@dataclass
class EventOnlySettings:
    """Used when the scene has no frames: ``α·L_ev + (1−α)·L_intensity`` (Event-3DGS)."""

    alpha_final: float = 0.95        # α after the warm-up and ramp (0.9-0.99)
    alpha_warmup: int = 300          # iterations with α = 0 (the intensity anchor only)
    alpha_ramp: int = 300            # iterations of linear ramp of α
    hpf_readouts: int = 200          # instants the HPF intensity image is precomputed at
    intensity_tau: float = 0.05      # τ of the HPF intensity image (s)
    anchor_highpass: float = 0.0     # > 0: the anchor compares only scales finer than a Gaussian
                                     # of this many pixels (priors.intensity_prior_loss)
    tv_weight: float = 0.0           # weight of the renders' total variation (priors.total_variation_prior;
                                     # fills what the motion leaves unobserved); 0 off
    tv_space: Literal["log", "srgb"] = "log"  # ... of the log intensity or of the sRGB image
    gradient_blur: float = 0.0       # σ (pixels) of the renders' smoothed log gradient added to the
                                     # gradient (priors.smooth_log_gradient); 0 off
    gradient_blur_weight: float = 1.0  # ... and its weight

    def __post_init__(self) -> None:
        _need_positive("event_only", self, ("anchor_highpass", "tv_weight", "gradient_blur",
                                            "gradient_blur_weight"), zero_ok=True)


@dataclass
class OptimSettings:
    iterations: int = 1500
    lr_means: float = 1.6e-4         # times the scene extent
    lr_means_final: float = 1.6e-6   # exponential decay to this (times the scene extent)
    lr_scales: float = 5e-3
    lr_quats: float = 1e-3
    lr_opacities: float = 5e-2
    lr_colors: float = 2.5e-3
    colour_step: Literal["linear", "relative"] = "linear"  # relative: each colour's Adam step is
                                     # scaled by max(level, colour_step_floor) / its start level
    colour_step_floor: float = 1e-3  # linear level below which the relative step stops shrinking
    colour_step_start: int = 0       # iteration from which the relative step applies
    lr_gain: float = 1e-3
    refine_poses: bool = True        # refine the trajectory knots jointly
    lr_pose: float = 1e-3            # camera learning rate, decayed to lr_pose_final
    lr_pose_final: float = 1e-5
    pose_start: int = 500            # iteration from which poses are refined

    def __post_init__(self) -> None:
        _need_positive("optim", self, ("lr_means", "lr_means_final", "lr_scales", "lr_quats",
                                       "lr_opacities", "lr_colors", "lr_gain", "lr_pose",
                                       "lr_pose_final", "colour_step_floor"))
        _need_positive("optim", self, ("colour_step_start",), zero_ok=True)


@dataclass
class DensifySettings:
    enabled: bool = True
    start: int = 300
    stop: int = 1300
    every: int = 100
    grad_threshold: float = 2e-4     # view-space gradient threshold (divided over the N renders)
    reset_opacity_every: int = 3000  # 0 disables; also disabled once events are on
    max_gaussians: int = 18000       # densification grows the Gaussians up to this count, no more
                                     # (the highest-gradient candidates first); 0 = no cap

    def __post_init__(self) -> None:
        if self.max_gaussians < 0:
            raise ConfigError("config", "densify.max_gaussians", "an integer >= 0 (0: no cap)",
                              repr(self.max_gaussians))


@dataclass
class OutputSettings:
    progress: bool = True            # progress bar with loss and PSNR
    video_fps: int = 12
    checkpoint_every: int = 1000     # 0: only at the end (and on Ctrl-C)
    exposure_ratio: bool = True      # deblurred = render x frame / predicted frame (outputs/)
    ratio_eps: float = 0.01          # its linear offset (keeps dark, noisy pixels from amplifying)
    ratio_iterations: int = 3        # 0: the ratio stays at its pixel over the exposure; N: it moves
                                     # with the surfaces, N Richardson-Lucy steps (outputs/motion_ratio.py)
    ratio_between: bool = True       # instants between two exposures (renders/, novel views): both
                                     # frames' factors carried there along the motion (ratio_iterations >= 1)
    truth_every: int = 100           # PSNR against gt/ every N iterations (history.jsonl); 0 = off
    exposure: Literal["auto", "none"] = "auto"  # scenes without frames: one linear gain puts the
                                     # renders' 99.5th percentile at 0.9 (their level is arbitrary);
                                     # none: as rendered (train/render_io.py: exposure_gain)
    ply_fit_steps: int = 100         # model.ply: Adam steps fitting its colours and opacities so that
                                     # 3DGS viewers, compositing them as stored, show the run's renders;
                                     # 0 = each Gaussian's colour sRGB-encoded (outputs/display_ply.py)

    def __post_init__(self) -> None:
        if self.ply_fit_steps < 0:
            raise ConfigError("config", "output.ply_fit_steps", "an integer >= 0 (0 = no fit)",
                              repr(self.ply_fit_steps))
        if not self.ratio_eps > 0:
            raise ConfigError("config", "output.ratio_eps", "a number > 0 (linear units)",
                              repr(self.ratio_eps))
        if self.ratio_iterations < 0:
            raise ConfigError("config", "output.ratio_iterations", "an integer >= 0 (0: per pixel)",
                              repr(self.ratio_iterations))
        if self.truth_every < 0:
            raise ConfigError("config", "output.truth_every", "an integer >= 0 (0 = off)",
                              repr(self.truth_every))
        if self.exposure not in ("auto", "none"):
            raise ConfigError("config", "output.exposure", "'auto' or 'none'", repr(self.exposure))


@dataclass
class ChunkSettings:
    seconds: float = 10.0            # a recording longer than this is deblurred in overlapping time
                                     # chunks, each with its own Gaussians and path (pipeline/chunks.py);
                                     # 0 = one piece whatever the length
    overlap: float = 1.0             # seconds shared by neighbouring chunks (a frame is taken from the
                                     # chunk in whose middle it lies)

    def __post_init__(self) -> None:
        _need_positive("chunk", self, ("seconds", "overlap"), zero_ok=True)
        if self.seconds and self.overlap >= self.seconds:
            raise ConfigError("config", "chunk.overlap", f"less than chunk.seconds ({self.seconds:g})",
                              repr(self.overlap))


@dataclass
class DeblurConfig:
    seed: int = 0
    backend: Literal["auto", "torch", "cpu", "gsplat"] = "auto"
    device: str = "cpu"              # torch device string for training, e.g. "cpu" or "cuda:0"
    trajectory: Literal["linear", "spline"] = "spline"
    knot_spacing: float = 0.02       # spline knot spacing (s); 0 = the pose samples' spacing
    init: InitSettings = field(default_factory=InitSettings)
    blur: BlurSettings = field(default_factory=BlurSettings)
    events: EventSettings = field(default_factory=EventSettings)
    threshold: ThresholdSettings = field(default_factory=ThresholdSettings)
    priors: PriorSettings = field(default_factory=PriorSettings)
    event_only: EventOnlySettings = field(default_factory=EventOnlySettings)
    optim: OptimSettings = field(default_factory=OptimSettings)
    densify: DensifySettings = field(default_factory=DensifySettings)
    output: OutputSettings = field(default_factory=OutputSettings)
    chunk: ChunkSettings = field(default_factory=ChunkSettings)
