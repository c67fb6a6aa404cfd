"""Every relative link in README.md and docs/*.md reaches a file that exists, and every #anchor a heading of it.

README's long sections live in docs/ pages that README links to (the new-user trial found a 1464-line README hard to
use as a reference); a page renamed or a heading reworded must not leave a link into nothing.
"""
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FENCED = re.compile(r"```.*?```", flags=re.S)


def github_anchor(heading: str) -> str:
    """The anchor GitHub gives a Markdown heading: lower case, punctuation dropped, spaces as hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """The anchors of every heading of ``page`` outside code blocks."""
    return {github_anchor(h) for h in re.findall(r"^#+\s+(.*)$", FENCED.sub("", page.read_text()), flags=re.M)}


def broken_links(pages: list[Path]) -> list[str]:
    """``page: target`` for each relative link whose file or anchor is missing (web addresses are not checked)."""
    broken = []
    for page in pages:
        for target in re.findall(r"\]\(([^)\s]+)\)", FENCED.sub("", page.read_text())):
            if re.match(r"[a-z]+:", target):
                continue
            path, _, anchor = target.partition("#")
            dest = (page.parent / path).resolve() if path else page.resolve()
            if not dest.exists() or (anchor and dest.suffix == ".md" and anchor not in anchors(dest)):
                broken.append(f"{page.name}: {target}")
    return broken


def test_github_anchor_of_headings_with_code_and_punctuation() -> None:
    assert github_anchor("Set up and run (fresh machine, Python ≥ 3.11)") == "set-up-and-run-fresh-machine-python--311"
    assert github_anchor("The result: `--json` and `<session>.result.json`") == "the-result---json-and-sessionresultjson"


def test_a_missing_page_and_a_missing_anchor_are_found(tmp_path: Path) -> None:
    page = tmp_path / "a.md"
    page.write_text("# Title\n\n[ok](#title) [gone](b.md) [bad anchor](#titel)\n\n```\n[in code](c.md)\n```\n")
    assert [b.split(": ", 1)[1] for b in broken_links([page])] == ["b.md", "#titel"]


def test_readme_and_docs_pages_link_only_to_what_exists() -> None:
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    assert len(pages) >= 9  # README, design.md and the pages README's long sections moved to
    assert broken_links(pages) == []
