"""Optional learned matting: rembg (U^2-Net on onnxruntime), used only for `--matting rembg` when
the user installed rembg and its weights are on disk; windowshop never downloads them."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from windowshop.errors import UserError

MODEL = "u2net"  # rembg's general-purpose model
THRESHOLD = 128  # alpha (0-255) above which a pixel is the object's


def weights_path() -> Path:
    """Where rembg keeps the model's weights ($U2NET_HOME, else ~/.u2net)."""
    home = Path(os.environ.get("U2NET_HOME", Path.home() / ".u2net")).expanduser()
    return home / f"{MODEL}.onnx"


def masks(images: list[np.ndarray]) -> list[np.ndarray]:
    """(H, W) bool object masks of `images` (H, W, 3) uint8 by rembg; UserError when rembg or
    its weights are missing."""
    try:
        from rembg import new_session, remove
    except ImportError:
        raise UserError("--matting rembg needs the rembg package: pip install 'rembg[cpu]', "
                        "then place its u2net.onnx weights in ~/.u2net (or $U2NET_HOME); or "
                        "leave out --matting to use the built-in segmentation") from None
    path = weights_path()
    if not path.is_file():
        raise UserError(f"--matting rembg: its weights are not on disk ({path}); download "
                        f"u2net.onnx there (windowshop never downloads models), or leave out "
                        f"--matting to use the built-in segmentation")
    session = new_session(MODEL)
    return [np.asarray(remove(image, session=session, only_mask=True)) >= THRESHOLD
            for image in images]
