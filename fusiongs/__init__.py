"""fusiongs: deblur blurry RGB video with an event camera and fit a 3D Gaussian Splatting scene.

The package is layered; lower layers never import higher ones::

    render/  scene/  camera/      Gaussian splatting, Gaussian parameters, poses in time
    events/  frames/  io/         data containers, readers, CFA, high-pass filter, simulator
    losses/  train/  eval/        the fusion method, its training loop and its evaluation
    cli.py                        ``fusiongs <verb>``
"""

import os as _os

# torch's and numba's OpenMP pools busy-wait against each other on few cores unless told to sleep
# (measured 3-10x slower CPU rendering on 2 cores); this must be set before torch is imported.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__version__ = "0.1.0"

from fusiongs.errors import FusionGSError, InputError

__all__ = ["FusionGSError", "InputError", "__version__"]
