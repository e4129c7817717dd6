"""docs/ and the README: every relative link points at a file that exists, and every stage
folder of splatting/ and the contract have their page."""
import os
import re

from helpers import ROOT

LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def pages():
    yield os.path.join(ROOT, "README.md")
    docs = os.path.join(ROOT, "docs")
    for f in sorted(os.listdir(docs)):
        if f.endswith(".md"):
            yield os.path.join(docs, f)


def test_relative_links_resolve():
    bad = []
    for page in pages():
        for target in LINK.findall(open(page).read()):
            if re.match(r"^[a-z]+:", target) or target.startswith("#"):
                continue
            path = os.path.normpath(os.path.join(os.path.dirname(page), target.split("#")[0]))
            if not os.path.exists(path):
                bad.append(f"{os.path.relpath(page, ROOT)} -> {target}")
    assert not bad, "\n".join(bad)


def test_link_check_sees_a_broken_link(tmp_path):
    page = tmp_path / "p.md"
    page.write_text("see [x](nowhere.md) and [y](https://example.org)")
    targets = LINK.findall(page.read_text())
    assert targets == ["nowhere.md", "https://example.org"]
    assert not os.path.exists(tmp_path / targets[0])


def test_contract_and_stage_pages_exist():
    for page in ("contract.md", "index.md", "rasterizer.md", "training.md", "parametric_bike.md", "rider.md",
                 "cyclists_and_datasets.md", "bikes_and_views.md", "curation.md"):
        assert os.path.isfile(os.path.join(ROOT, "docs", page)), page
