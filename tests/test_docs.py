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


def broken_links(page_paths, root=ROOT):
    """'page -> target' for every relative link whose file does not exist (URLs and #anchors skipped)."""
    bad = []
    for page in page_paths:
        for target in LINK.findall(open(page).read()):
            if re.match(r"^[a-z]+:", target) or target.startswith("#"):
                continue
            path = os.path.normpath(os.path.join(os.path.dirname(page), target.split("#")[0]))
            if not os.path.exists(path):
                bad.append(f"{os.path.relpath(page, root)} -> {target}")
    return bad


def test_relative_links_resolve():
    bad = broken_links(pages())
    assert not bad, "\n".join(bad)


def test_link_check_sees_a_broken_link(tmp_path):
    """The checker itself on a temporary doc: the broken relative link (also one with an anchor and one
    into a missing folder) is reported, the good link, the URL and the anchor are not."""
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "there.md").write_text("x")
    page = tmp_path / "p.md"
    page.write_text("see [x](nowhere.md), [g](sub/there.md#a), [h](sub/gone.md#b), [n](no/dir.png), "
                    "[y](https://example.org) and [z](#top)")
    assert broken_links([str(page)], str(tmp_path)) == ["p.md -> nowhere.md", "p.md -> sub/gone.md#b",
                                                        "p.md -> no/dir.png"]


def test_contract_and_stage_pages_exist():
    for page in ("contract.md", "index.md", "rasterizer.md", "training.md", "parametric_bike.md", "rider.md",
                 "cyclists_and_datasets.md", "bikes_and_views.md", "curation.md"):
        assert os.path.isfile(os.path.join(ROOT, "docs", page)), page
