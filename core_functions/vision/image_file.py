"""Reading an image file safely: a size limit, OpenCV's decoders only, one clear error naming the file."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

#: Largest image file read (bytes): a camera image, not whatever a path points at.
MAX_IMAGE_BYTES = 64 * 1024 * 1024


class ImageFileError(ValueError):
    """The file is missing, too large or not an image; the message names it."""


def read_image(path: Path) -> NDArray[np.uint8]:
    """An image file (PNG, JPEG, TIFF, BMP, PGM, ...) as an 8-bit mono array."""
    try:
        size = path.stat().st_size
    except OSError as error:
        raise ImageFileError(f"{path}: {error.strerror or error}") from None
    if not path.is_file():
        raise ImageFileError(f"{path}: not a file")
    if size > MAX_IMAGE_BYTES:
        raise ImageFileError(f"{path}: {size} bytes, larger than the {MAX_IMAGE_BYTES} bytes an image may have")
    try:
        data = np.fromfile(str(path), dtype=np.uint8)
    except OSError as error:
        raise ImageFileError(f"{path}: {error.strerror or error}") from None
    image = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE) if data.size else None
    if image is None:
        raise ImageFileError(f"{path}: not an image OpenCV can read (PNG, JPEG, TIFF, BMP, PGM, ...)")
    return image
