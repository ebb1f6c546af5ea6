"""``fusiongs view OUT``: a finished run in the browser (viser), until Ctrl-C.

The page opens at the first frame's fitted pose and shows the Gaussians of ``OUT/model.ply`` as
3DGS viewers draw them, the fitted camera path with a frustum at each frame's mid-exposure (a
click shows that frame blurry | deblurred) and a time slider that moves the camera along the path
and shows fusiongs' own render at that instant. CPU only is fine: the browser draws the Gaussians,
and the renders are one image at a time.
"""

from __future__ import annotations

import argparse

HELP = "show a finished deblur run in the browser: its Gaussians, fitted camera path, frames and sharp views"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="output folder of `fusiongs deblur` (holds checkpoint.pt and model.ply)")
    p.add_argument("--port", type=int, default=8080, help="port to serve the page on (default 8080)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1, this machine only; 0.0.0.0: every "
                        "network interface)")
    p.add_argument("--scene", default=None,
                   help="the run's scene folder, for the blurry frames when it has moved, and to place the "
                        "frames of a run written before OUT/frames.json existed")


def run(args: argparse.Namespace) -> int:
    import signal
    import threading
    from pathlib import Path

    from fusiongs.view.run import check_run_folder, load_run
    from fusiongs.view.server import check_port, start_viewer

    root = Path(args.run)
    check_run_folder(root)  # the cheap checks first: a wrong folder or a busy port in a moment
    check_port(args.host, args.port)
    loaded = load_run(root, Path(args.scene) if args.scene else None)
    for note in loaded.frames.notes:
        print(f"fusiongs view: {note}")
    viewer = start_viewer(loaded, args.host, args.port)
    host = "localhost" if args.host in ("0.0.0.0", "::") else args.host
    print(f"fusiongs view: http://{host}:{viewer.server.get_port()} (Ctrl-C to stop)", flush=True)
    stop = threading.Event()  # Ctrl-C or a plain kill (SIGTERM) ends the viewer normally
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        while not stop.wait(0.5):
            pass
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        viewer.stop()
    return 0
