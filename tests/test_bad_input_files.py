"""Bad input families that once got through (issue 25): a config that is not UTF-8, a dataset name
that would write outside its output root, a Ray address where nothing listens.  Each ends with a
non-zero exit, one line on stderr naming the problem, no traceback, nothing written, within seconds."""
import os
import shutil
import socket
import time

import pytest

from cyclist_formats.errors import UserError
from cyclist_formats.text_files import read_json, read_text, read_yaml


def snapshot(root):
    return sorted(os.path.relpath(os.path.join(d, n), root) for d, ds, fs in os.walk(root) for n in ds + fs)


def refuse(argv, work, capsys, monkeypatch):
    from splatting.cli import main

    monkeypatch.chdir(work)
    before = snapshot(work)
    try:
        code = main(argv)
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err
    lines = err.strip("\n").split("\n")
    assert code not in (0, None), f"exit {code}: {err}"
    assert len(lines) == 1 and "error" in lines[0] and "Traceback" not in err, err
    assert snapshot(work) == before, "a refused command wrote something"
    return lines[0]


def test_a_config_that_is_not_utf8_is_one_line(tmp_path, capsys, monkeypatch):
    (tmp_path / "latin1.yaml").write_bytes("name: vélo\ncount: 2\n".encode("latin-1"))
    line = refuse(["dataset", "--config", "latin1.yaml", "--out", "d"], tmp_path, capsys, monkeypatch)
    assert "latin1.yaml" in line and "UTF-8" in line and "0xe9" in line


def test_the_text_readers_name_the_file(tmp_path):
    p = tmp_path / "x.yaml"
    p.write_bytes(b"a: \xff\n")
    for read in (read_text, read_yaml, read_json):
        with pytest.raises(UserError, match="x.yaml.*UTF-8"):
            read(str(p))
    p.write_bytes(b"a: [1\n")
    with pytest.raises(UserError, match="is not valid YAML"):
        read_yaml(str(p))
    with pytest.raises(UserError, match="is not valid JSON"):
        read_json(str(p))
    with pytest.raises(UserError, match="gone"):
        read_yaml(str(tmp_path / "none.yaml"), missing="gone")
    p.write_text("a: 1\nb: [x, y]\n", encoding="utf-8")
    assert read_yaml(str(p)) == {"a": 1, "b": ["x", "y"]}


def test_a_bad_roster_is_one_line(tmp_path):
    from splatting.rider.roster import load_roster

    p = tmp_path / "riders.yaml"
    p.write_bytes(b"riders:\n  - id: \xe9\n")
    with pytest.raises(UserError, match="bad YAML in .*riders.yaml.*UTF-8"):
        load_roster(p)


@pytest.mark.parametrize("name", ["../../escape", "a/b", "..", ".hidden", "", "x" * 101, "sp ace"])
def test_a_dataset_name_cannot_leave_the_output_root(tmp_path, capsys, monkeypatch, name):
    (tmp_path / "work").mkdir()
    (tmp_path / "work" / "cfg.yaml").write_text(f"name: {name!r}\ncount: 1\n")
    line = refuse(["dataset", "--config", "cfg.yaml"], tmp_path / "work", capsys, monkeypatch)
    assert "'name'" in line, line
    assert not (tmp_path / "escape").exists()


def test_a_safe_name_is_accepted():
    from splatting.dataset.config import DEFAULTS, validate

    for name in ("cyclist", "bike-only", "demo_street", "v1.2"):
        assert validate(dict(DEFAULTS, name=name)).name == name


def test_the_output_root_check_resolves_links(tmp_path):
    from cyclist_formats.checks import inside

    (tmp_path / "root").mkdir()
    (tmp_path / "elsewhere").mkdir()
    os.symlink(tmp_path / "elsewhere", tmp_path / "root" / "link")
    assert inside(str(tmp_path / "root"), str(tmp_path / "root" / "a" / "b"), "out")
    with pytest.raises(UserError, match="outside"):
        inside(str(tmp_path / "root"), str(tmp_path / "root" / "link" / "x"), "out")
    with pytest.raises(UserError, match="outside"):
        inside(str(tmp_path / "root"), str(tmp_path / "root" / ".." / "x"), "out")


def _closed_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]  # closed again when the block ends: nothing listens there


@pytest.mark.parametrize("command", [["dataset", "--preset", "cyclist", "--out", "d"], ["library build", "--out", "lib"]])
def test_a_ray_address_where_nothing_listens_fails_in_seconds(tmp_path, capsys, monkeypatch, command):
    argv = command[0].split() + command[1:] + ["--engine", "ray", "--address", f"127.0.0.1:{_closed_port()}"]
    t = time.time()
    line = refuse(argv, tmp_path, capsys, monkeypatch)
    assert time.time() - t < 10, "the address check took too long"
    assert "no Ray cluster answers" in line, line


@pytest.mark.parametrize("address", ["nowhere", "host:port", "10.0.0.1:0", "10.0.0.1:70000"])
def test_a_malformed_ray_address_is_one_line(tmp_path, capsys, monkeypatch, address):
    line = refuse(["dataset", "--preset", "cyclist", "--out", "d", "--engine", "ray", "--address", address],
                  tmp_path, capsys, monkeypatch)
    assert "HOST:PORT" in line, line


def test_a_listening_address_passes_the_probe():
    from splatting.library.ray_address import check_address

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        addr = f"127.0.0.1:{s.getsockname()[1]}"
        assert check_address(addr) == addr
        assert check_address("ray://" + addr) == "ray://" + addr
    assert check_address("auto") == "auto" and check_address(None) is None


@pytest.mark.parametrize("content", [b"\xff\xfe{}", b"{not json", b"[1, 2]"])
def test_a_damaged_dataset_record_is_one_line(tmp_path, capsys, monkeypatch, content):
    """An --out holding a config.json that is not a dataset's record (not UTF-8, not JSON, not an
    object) is refused in one line before any sample is drawn."""
    import yaml

    from helpers import ROOT, small_config

    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "config.json").write_bytes(content)
    shutil.copytree(os.path.join(ROOT, "blend_assets", "stand_in_bike"), tmp_path / "bikes")
    (tmp_path / "cfg.yaml").write_text(yaml.safe_dump(small_config(str(tmp_path / "bikes"), count=1, bikes=["city_00"])))
    from splatting.cli import main

    monkeypatch.chdir(tmp_path)
    code = main(["dataset", "--config", "cfg.yaml", "--out", "d", "--quiet"])
    err = capsys.readouterr().err
    assert code not in (0, None) and len(err.strip().split("\n")) == 1 and "config.json" in err, err
    assert sorted(os.listdir(tmp_path / "d")) == ["config.json"]


def test_bikes_and_riders_on_the_command_line_override_the_config(tmp_path, capsys, monkeypatch):
    """`dataset --bikes ID... --riders ID... --riders-root DIR`: following one bike needs no YAML.
    The overrides reach the config: an unknown id among them is refused naming it."""
    from splatting.dataset.config import load_config

    cfg = load_config(None, "cyclist", {"bikes": ["city_00", "road_01"], "riders": ["m_adult_average_185"],
                                        "riders_root": "somewhere"})
    assert cfg.bikes == ["city_00", "road_01"] and cfg.riders == ["m_adult_average_185"]
    assert cfg.riders_root == "somewhere"
    shutil.copytree(os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "blend_assets",
                                 "stand_in_bike"), tmp_path / "bikes")
    base = ["dataset", "--preset", "cyclist", "--bikes-root", "bikes", "--out", "d", "--count", "1"]
    line = refuse(base + ["--bikes", "city_00", "no_such_bike"], tmp_path, capsys, monkeypatch)
    assert "no_such_bike" in line and "'bikes'" in line, line
    line = refuse(base + ["--bikes", "city_00", "--riders", "no_such_rider"], tmp_path, capsys, monkeypatch)
    assert "no_such_rider" in line and "'riders'" in line, line
