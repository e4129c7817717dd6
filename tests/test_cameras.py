import json

import pytest

from splatting.raster.camera import load_cameras, ring_camera
from cyclist_formats.errors import UserError


def test_load_cameras_bad_files_are_user_errors(tmp_path):
    binary = tmp_path / "cameras.json"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(UserError, match="not valid JSON"):
        load_cameras(binary)
    with pytest.raises(UserError, match="no cameras file"):
        load_cameras(tmp_path / "missing.json")
    with pytest.raises(UserError, match="cannot read"):
        load_cameras(tmp_path)  # a folder
    (tmp_path / "empty.json").write_text(json.dumps({"orbit_centre": [0, 0, 0]}))
    with pytest.raises(UserError, match="no cameras"):
        load_cameras(tmp_path / "empty.json")


def test_load_cameras_reads_ring_layout(tmp_path):
    c = ring_camera(30, (0.0, 0.5, 0.0))
    (tmp_path / "c.json").write_text(json.dumps({"camera0003": {"K": c.K.tolist(), "R": c.R.tolist(), "T": c.T.tolist()},
                                                 "orbit_centre": [0.0, 0.5, 0.0]}))
    cams, orbit = load_cameras(tmp_path / "c.json")
    assert len(cams) == 1 and cams[0].name == "camera0003" and cams[0].width == 512 and orbit == [0.0, 0.5, 0.0]
    assert (cams[0].centre - c.centre).abs().max() < 1e-5
