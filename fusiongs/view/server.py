"""The page ``fusiongs view`` serves (viser): the Gaussians of ``model.ply``, the fitted path with a
camera frustum at each frame's mid-exposure, each frame blurry | deblurred on a click, and a time
slider that moves the camera along the path and shows fusiongs' own render at that instant.

The page opens at the first frame's fitted pose with the camera's vertical field of view, so a
browser window of the camera's aspect shows what the frame shows.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import socket
import threading
from collections.abc import Callable

import numpy as np

from fusiongs.errors import InputError, MissingDependencyError
from fusiongs.view.geometry import ViewPose, fov_y, scene_depth, splats_from_ply, view_pose
from fusiongs.view.run import LoadedRun, ViewFrame, blurry_image, run_image, side_by_side

PATH_SAMPLES = 400  # points of the drawn path
SLIDER_STEPS = 1000  # positions of the time slider over the path
FRUSTUM_SHARE = 0.08  # a frustum's depth, as a share of the opening view's median scene depth ...
FRUSTUM_SPACING = 0.3  # ... and at most this share of the distance between consecutive frames
PANEL_WIDTH = 320  # px: the panel's images are enlarged to about this width
LINES = {"thickness": 1.5, "thickness_units": "screen"}  # frustum lines, px (they frame the view)
TRAINED_COLOUR = (40, 110, 230)
HELD_OUT_COLOUR = (240, 140, 20)
RENDER_COLOUR = (40, 170, 80)


def check_port(host: str, port: int) -> None:
    """Raise unless ``host:port`` can be listened on now.

    Raises:
        InputError: naming ``--port`` (or ``--host``) and why.
    """
    if not 0 <= port <= 65535:
        raise InputError("fusiongs view", "--port", "a port number in [0, 65535]", port)
    try:
        family, _, _, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
    except OSError as e:
        raise InputError("fusiongs view", "--host", "a host name or address of this machine",
                         f"{host} ({e})") from None
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server itself binds
        try:
            s.bind(address)
        except OSError as e:
            raise InputError("fusiongs view", "--port", f"a free port on {host}",
                             f"{port}, in use ({e.strerror})") from None


class Latest:
    """Calls ``fn(value)`` for the newest requested value only, one call at a time: requests that
    queued up behind a running call are dropped but the last (a dragged slider renders once)."""

    def __init__(self, fn: Callable[[float], None]):
        self.fn, self.lock, self.wanted = fn, threading.Lock(), None

    def __call__(self, value: float) -> None:
        self.wanted = value
        with self.lock:
            if self.wanted == value:
                self.fn(value)


def enlarged(img: np.ndarray | None, width: int = PANEL_WIDTH) -> np.ndarray | None:
    """``img`` ``[H, W, 3]`` repeated by the whole factor that brings it nearest ``width`` px wide
    (never shrunk): a small camera's images stay visible in the panel."""
    if img is None:
        return None
    k = max(1, round(width / img.shape[1]))
    return np.ascontiguousarray(np.repeat(np.repeat(img, k, axis=0), k, axis=1)) if k > 1 else img


def frustum_scale(c2w: np.ndarray, depth: float) -> float:
    """The depth (scene units) of the frames' frustums: :data:`FRUSTUM_SHARE` of the scene depth,
    at most :data:`FRUSTUM_SPACING` of the median distance between consecutive frames' centres
    (``c2w`` ``[F, 4, 4]``), so that the neighbours of the camera the page opens at stay small."""
    steps = np.linalg.norm(np.diff(np.asarray(c2w)[:, :3, 3], axis=0), axis=1)
    steps = steps[steps > 0]
    scale = FRUSTUM_SHARE * depth
    return min(scale, FRUSTUM_SPACING * float(np.median(steps))) if steps.size else scale


def frame_view(run: LoadedRun, frame: ViewFrame) -> tuple[str, np.ndarray | None]:
    """The caption and the image (uint8 blurry | deblurred, or None) of one frame of ``run``."""
    blurry, missing = None, ""
    if run.frames.scene is not None:
        try:
            blurry = blurry_image(run.frames.scene, frame)
        except InputError as e:
            missing = f" ({e})"
    deblurred = run_image(run.root / "deblurred" / f"{frame.name}.png")
    held = "" if frame.trained else ", held out"
    caption = (f"frame **{frame.name}** ({frame.t_start:.4f} to {frame.t_end:.4f} s{held}): "
               f"{'blurry' if blurry is not None else 'no blurry frame'} | "
               f"{'deblurred' if deblurred is not None else 'no deblurred frame'}{missing}")
    return caption, side_by_side(blurry, deblurred)


@dataclasses.dataclass
class RunViewer:
    """The served page of a run and its live elements (what the callbacks change).

    Attributes:
        server: the ``viser.ViserServer``.
        run: the run shown.
        depth: the opening view's median scene depth (scene units): the orbit distance.
        opening: the opening camera.
        slider, follow, sharp, sharp_label, frame_image, frame_label: the panel's time slider,
            "camera follows the path" checkbox, sharp render and its caption, frame image and its
            caption (viser GUI handles).
        frustums: the cameras' frustums (viser scene handles).
    """

    server: object
    run: LoadedRun
    depth: float
    opening: ViewPose
    slider: object = None
    follow: object = None
    sharp: object = None
    sharp_label: object = None
    frame_image: object = None
    frame_label: object = None
    frustums: list = dataclasses.field(default_factory=list)

    def stop(self) -> None:
        """Stop serving (quietly: the command says what it does)."""
        with contextlib.redirect_stdout(io.StringIO()):
            self.server.stop()

    def move_cameras(self, t: float) -> None:
        """Put every connected browser's camera at instant ``t`` (s) of the fitted path."""
        p = view_pose(self.run.c2w([t])[0], self.depth)
        for client in self.server.get_clients().values():
            with client.atomic():
                client.camera.wxyz = p.wxyz
                client.camera.position = p.position

    def show_instant(self, t: float) -> None:
        """The slider's action: the cameras to ``t`` (when they follow), fusiongs' render at ``t``."""
        if self.follow.value:
            self.move_cameras(t)
        self.sharp.image = enlarged(self.run.sharp_view(t))
        self.sharp_label.content = f"fusiongs render at t = {t:.4f} s"

    def show_frame(self, frame: ViewFrame, move: bool = True) -> None:
        """A frame's click: blurry | deblurred in the panel and, with ``move``, the slider (and the
        cameras) to its mid-exposure."""
        self.frame_label.content, pair = frame_view(self.run, frame)
        if pair is not None:
            self.frame_image.image, self.frame_image.visible = enlarged(pair), True
        if move:
            self.slider.value = float(np.clip(frame.t_mid, *self.run.t_range))

    def show_render(self, name: str, t: float) -> None:
        """A render instant's click: ``renders/<name>.png`` in the panel, the slider to ``t``."""
        img = run_image(self.run.root / "renders" / f"{name}.png")
        self.frame_label.content = f"render **{name}** at t = {t:.4f} s (renders/{name}.png)"
        if img is not None:
            self.frame_image.image, self.frame_image.visible = enlarged(img), True
        self.slider.value = float(np.clip(t, *self.run.t_range))


def _scene(v: RunViewer) -> None:
    """The 3D scene: Gaussians, path, frustums (clickable), the opening camera."""
    run, server, cam, pose = v.run, v.server, v.run.camera, v.opening
    splats = splats_from_ply(run.ply)
    server.scene.set_up_direction(tuple(pose.up))
    server.scene.set_background_image(np.zeros((8, 8, 3), np.uint8), format="png")  # renders are over black
    server.initial_camera.fov = fov_y(cam)
    server.initial_camera.near = max(1e-4, 1e-3 * v.depth)
    server.initial_camera.position = tuple(pose.position)
    server.initial_camera.look_at = tuple(pose.look_at)
    server.initial_camera.up = tuple(pose.up)
    server.scene.add_gaussian_splats("/gaussians", centers=splats.centers, covariances=splats.covariances,
                                     rgbs=splats.rgbs, opacities=splats.opacities)
    path = run.c2w(np.linspace(*run.t_range, PATH_SAMPLES))[:, :3, 3]
    server.scene.add_spline_catmull_rom("/path", points=path, color=TRAINED_COLOUR, thickness=2.0,
                                        thickness_units="screen")
    frames = run.frames.frames
    mids = [f.t_mid for f in frames]
    poses = run.c2w(mids) if mids else np.zeros((0, 4, 4))
    aspect, fov, scale = cam.width / cam.height, fov_y(cam), frustum_scale(poses, v.depth)
    for frame, c2w in zip(frames, poses):
        p = view_pose(c2w, v.depth)
        handle = server.scene.add_camera_frustum(
            f"/frames/{frame.name}", fov=fov, aspect=aspect, scale=scale, wxyz=p.wxyz, position=p.position,
            color=TRAINED_COLOUR if frame.trained else HELD_OUT_COLOUR, **LINES)
        handle.on_click(lambda _, f=frame: v.show_frame(f))
        v.frustums.append(handle)
    renders = [(n, t) for n, t in run.frames.renders if not np.any(np.isclose(t, mids, rtol=0, atol=1e-6))]
    for (name, t), c2w in zip(renders, run.c2w([t for _, t in renders]) if renders else []):
        p = view_pose(c2w, v.depth)
        handle = server.scene.add_camera_frustum(
            f"/renders/{name}", fov=fov, aspect=aspect, scale=0.6 * scale, wxyz=p.wxyz, position=p.position,
            color=RENDER_COLOUR, **LINES)
        handle.on_click(lambda _, n=name, tt=t: v.show_render(n, tt))
        v.frustums.append(handle)


def _panel(v: RunViewer) -> None:
    """The panel: what the run is, the time slider and its render, the clicked frame."""
    run, gui = v.run, v.server.gui
    t_min, t_max = run.t_range
    lines = [f"**{run.root.name}**: {run.ply.n} Gaussians (model.ply), {len(run.frames.frames)} frames, "
             f"path {t_min:.3f} to {t_max:.3f} s. Click a camera for its frame."]
    gui.add_markdown("  \n".join(lines + [f"*{note}*" for note in run.frames.notes]))
    step = max((t_max - t_min) / SLIDER_STEPS, 1e-6)
    v.slider = gui.add_slider("time (s)", min=t_min, max=max(t_max, t_min + step), step=step,
                              initial_value=run.t_open)
    v.follow = gui.add_checkbox("camera follows the path", initial_value=True)
    cameras = gui.add_checkbox("show the cameras", initial_value=True)
    cameras.on_update(lambda _: [setattr(h, "visible", cameras.value) for h in v.frustums])
    v.sharp_label = gui.add_markdown(f"fusiongs render at t = {run.t_open:.4f} s")
    v.sharp = gui.add_image(enlarged(run.sharp_view(run.t_open)), format="png")
    v.frame_label = gui.add_markdown("")
    v.frame_image = gui.add_image(np.zeros((2, 2, 3), np.uint8), format="png", visible=False)
    back = gui.add_button("back to the first view")
    latest = Latest(v.show_instant)
    v.slider.on_update(lambda _: latest(float(v.slider.value)))
    back.on_click(lambda _: (setattr(v.slider, "value", run.t_open), v.move_cameras(run.t_open)))
    if run.frames.frames:
        v.show_frame(run.frames.frames[0], move=False)


def start_viewer(run: LoadedRun, host: str = "127.0.0.1", port: int = 8080) -> RunViewer:
    """Build the page of ``run`` and serve it at ``http://host:port`` (returns at once; the server
    runs in its own threads until :meth:`RunViewer.stop`).

    Raises:
        MissingDependencyError: viser is not installed.
        InputError: the port was taken meanwhile.
    """
    try:
        import viser
    except ImportError:
        raise MissingDependencyError("viser", "fusiongs view") from None

    with contextlib.redirect_stdout(io.StringIO()):  # viser's own banner: the command prints the address
        server = viser.ViserServer(host=host, port=port, label="fusiongs view", verbose=False)
    if port and server.get_port() != port:  # viser moves on to the next free port; we do not
        server.stop()
        raise InputError("fusiongs view", "--port", f"a free port on {host}", f"{port}, in use")
    c2w_open = run.c2w([run.t_open])[0]
    depth = scene_depth(run.ply.means.detach().cpu().numpy(), c2w_open)
    v = RunViewer(server, run, depth, view_pose(c2w_open, depth))
    _scene(v)
    _panel(v)
    return v
