"""splatting/dataset/png.py: the dataset's PNG writer gives files that Pillow (an independent
decoder) reads back to exactly the pixels written, for RGB uint8 and 16-bit depth maps."""
import io

import numpy as np
import pytest
from PIL import Image

from splatting.dataset import png


@pytest.mark.parametrize("level", [0, 1, 4, 9])
@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (5, 1), (37, 53)])
def test_rgb_round_trip(level, shape):
    rng = np.random.default_rng(level * 100 + shape[1])
    img = rng.integers(0, 256, shape + (3,), dtype=np.uint8)
    img[: shape[0] // 2] = 255 - img[: shape[0] // 2]  # wraps in the Up filter's differences
    back = Image.open(io.BytesIO(png.encode(img, level)))
    assert back.mode == "RGB" and back.size == (shape[1], shape[0])
    assert (np.asarray(back) == img).all()


def test_uint16_round_trip_keeps_every_bit():
    rng = np.random.default_rng(3)
    img = rng.integers(0, 65536, (19, 23), dtype=np.uint16)
    img[0, :4] = [0, 1, 256, 65535]
    back = Image.open(io.BytesIO(png.encode(img, 4)))
    assert back.size == (23, 19)
    assert (np.asarray(back).astype(np.int64) == img.astype(np.int64)).all()


def test_smooth_images_compress():
    y, x = np.mgrid[0:64, 0:64]
    img = np.stack([x * 4, y * 4, (x + y) * 2], -1).astype(np.uint8)
    assert len(png.encode(img, 4)) < img.nbytes / 10


@pytest.mark.parametrize("bad", [np.zeros((4, 4, 4), np.uint8), np.zeros((4, 4, 3), np.float32),
                                 np.zeros((4, 4), np.uint8), np.zeros((0, 4, 3), np.uint8)])
def test_other_arrays_are_refused(bad):
    with pytest.raises(ValueError):
        png.encode(bad)
