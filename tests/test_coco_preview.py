import json

import numpy as np
from PIL import Image
from pycocotools import mask as mask_utils

from splatting.dataset.preview import COLOURS, coco_preview


def test_preview_tints_masks_and_draws_keypoints(tmp_path):
    (tmp_path / "images").mkdir()
    Image.fromarray(np.full((64, 64, 3), 200, np.uint8)).save(tmp_path / "images" / "000000.png")
    m = np.zeros((64, 64), np.uint8, order="F")
    m[10:30, 10:30] = 1
    rle = mask_utils.encode(m)
    rle["counts"] = rle["counts"].decode()
    ann = {"images": [{"id": 1, "file_name": "000000.png", "width": 64, "height": 64}],
           "categories": [{"id": 1, "name": "person"}],
           "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "segmentation": rle, "bbox": [10, 10, 20, 20],
                            "keypoints": [50, 50, 2], "num_keypoints": 1}]}
    (tmp_path / "annotations.json").write_text(json.dumps(ann))
    out = tmp_path / "p.png"
    assert coco_preview(str(tmp_path), str(out), tile=64) == 1
    p = np.asarray(Image.open(out).convert("RGB")).astype(int)
    expected = 0.6 * 200 + 0.4 * np.array(COLOURS["person"])
    assert np.abs(p[20, 20] - expected).max() <= 1  # inside the mask: tinted
    assert (p[5, 40] == 200).all()  # outside everything: untouched
    assert tuple(p[50, 50]) == (255, 255, 0)  # a visible keypoint
