"""The repository's documentation holds together: design citations in the code resolve to
sections of docs/design.md, relative links point at files (and headings) that exist, the
README stays short, and its two commands are the ones CI runs."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "docs" / "design.md"
README = ROOT / "README.md"
CODE_PACKAGES = ("mrslam_env", "agents", "scenarios", "tests")
DOCUMENTS = sorted([README, *(ROOT / "docs").glob("*.md")])

RUN_COMMAND = "python3 -m venv .venv && .venv/bin/pip install -e . && .venv/bin/mrslam run"

# "docs/design.md §5 step 3", "design §6", "docs/design.md §2, §4", "§5 steps 1–4", "§5 step
# 5, §6": a citation is "design" then one or more sections, each with optional steps.
CITATION = re.compile(
    r"design(?:\.md)?\s+(§\d+(?:\s+steps?\s+\d+(?:\s*[–-]\s*\d+)?)?"
    r"(?:(?:,\s*|\s+and\s+)§\d+(?:\s+steps?\s+\d+(?:\s*[–-]\s*\d+)?)?)*)"
)
CITED_SECTION = re.compile(r"§(\d+)(?:\s+steps?\s+(\d+)(?:\s*[–-]\s*(\d+))?)?")
NUMBERED_HEADING = re.compile(r"^## (\d+)\. ", re.MULTILINE)
FENCE = re.compile(r"^(```|~~~).*?^\1[ \t]*$", re.MULTILINE | re.DOTALL)
LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")


def without_code(markdown: str) -> str:
    """Markdown without fenced code blocks and inline code spans."""
    return re.sub(r"`[^`\n]*`", "", FENCE.sub("", markdown))


def citations() -> list[tuple[str, int, int | None]]:
    """Every (file, section, step) cited in the Python files of the code packages; a
    range of steps counts each step."""
    found: list[tuple[str, int, int | None]] = []
    for package in CODE_PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            name = str(path.relative_to(ROOT))
            for citation in CITATION.finditer(path.read_text(encoding="utf-8")):
                for section, first, last in CITED_SECTION.findall(citation.group(1)):
                    if not first:
                        found.append((name, int(section), None))
                        continue
                    for step in range(int(first), int(last or first) + 1):
                        found.append((name, int(section), step))
    return found


def design_sections() -> dict[int, str]:
    """The numbered sections of docs/design.md: number -> text up to the next ``## ``."""
    text = DESIGN.read_text(encoding="utf-8")
    sections: dict[int, str] = {}
    for match in NUMBERED_HEADING.finditer(text):
        end = text.find("\n## ", match.end())
        sections[int(match.group(1))] = text[match.start() : end if end >= 0 else len(text)]
    return sections


def heading_anchors(markdown: str) -> set[str]:
    """GitHub's anchors for the headings of a Markdown text (duplicates get -1, -2 ...)."""
    anchors: set[str] = set()
    seen: dict[str, int] = {}
    for line in without_code(markdown).splitlines():
        heading = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not heading:
            continue
        slug = re.sub(r"[^\w\- ]", "", heading.group(1).lower()).replace(" ", "-")
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        anchors.add(slug if count == 0 else f"{slug}-{count}")
    return anchors


def relative_links_in(markdown: str) -> list[str]:
    """Link and image targets of a Markdown text that are not URLs (code left out)."""
    targets = LINK.findall(without_code(markdown))
    return [t for t in targets if not re.match(r"^[a-z][a-z0-9+.-]*:", t, re.IGNORECASE)]


def relative_links(document: Path) -> list[str]:
    return relative_links_in(document.read_text(encoding="utf-8"))


def command_blocks(section: str) -> list[str]:
    """The bash blocks of a README section, each as its one command."""
    text = README.read_text(encoding="utf-8")
    start = text.index(f"\n## {section}\n")
    end = text.find("\n## ", start + 1)
    body = text[start : end if end >= 0 else len(text)]
    return [block.strip() for block in re.findall(r"^```bash\n(.*?)^```", body, re.M | re.S)]


# --- (a) design citations ------------------------------------------------------------------


def test_design_sections_are_numbered_one_to_nine() -> None:
    assert sorted(design_sections()) == list(range(1, 10))
    numbers = [int(n) for n in NUMBERED_HEADING.findall(DESIGN.read_text(encoding="utf-8"))]
    assert numbers == list(range(1, 10)), "numbered sections out of order or repeated"


def test_the_code_cites_design_sections() -> None:
    # The scan must find the citations, or the next test proves nothing.
    cited = citations()
    assert len(cited) > 20
    assert {section for _, section, _ in cited} >= {2, 5}


def test_every_design_citation_resolves() -> None:
    sections = design_sections()
    missing = []
    for name, section, step in citations():
        if section not in sections:
            missing.append(f"{name}: §{section} (no '## {section}.' heading in docs/design.md)")
        elif step is not None and f"**Step {step} —" not in sections[section]:
            missing.append(f"{name}: §{section} step {step} (no '**Step {step} —' there)")
    assert not missing, "\n".join(sorted(set(missing)))


# --- (b) the README stays short --------------------------------------------------------------


def test_readme_is_under_150_lines() -> None:
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) < 150, f"README.md has {len(lines)} lines; move detail into docs/"


# --- (c) relative links ----------------------------------------------------------------------


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_point_at_existing_files(document: Path) -> None:
    broken = []
    for target in relative_links(document):
        path_part, _, anchor = target.partition("#")
        path = (document.parent / path_part).resolve() if path_part else document
        if not path.exists():
            broken.append(f"{target}: no such file")
        elif (
            anchor
            and path.suffix == ".md"
            and anchor not in heading_anchors(path.read_text(encoding="utf-8"))
        ):
            broken.append(f"{target}: no heading with anchor #{anchor}")
    assert not broken, f"{document.relative_to(ROOT)}:\n" + "\n".join(broken)


def test_documents_name_no_machine_paths() -> None:
    for document in DOCUMENTS:
        text = document.read_text(encoding="utf-8")
        found = re.findall(r"(?<![\w.~])/(?:work|home|tmp|root|Users)/\S*", text)
        assert not found, f"{document.relative_to(ROOT)} names machine paths: {found}"


def test_the_link_checker_sees_links() -> None:
    targets = relative_links(README)
    assert "docs/design.md" in targets and "docs/office.png" in targets
    assert relative_links_in("[a](https://example.org) `[b](no.md)` ![c](d.png#e)") == ["d.png#e"]


# --- (d) the README's two commands -----------------------------------------------------------


def test_readme_commands_are_the_ones_ci_runs() -> None:
    ci_lines = [line for line in (ROOT / ".ci" / "run").read_text().splitlines() if line.strip()]
    test_command = ci_lines[-1].strip()
    assert command_blocks("Two commands") == [RUN_COMMAND, test_command]


# --- the README's Python ---------------------------------------------------------------------


def test_readme_python_blocks_parse() -> None:
    text = README.read_text(encoding="utf-8")
    blocks = re.findall(r"^```python\n(.*?)^```", text, re.M | re.S)
    assert blocks
    for block in blocks:
        ast.parse(block)
