"""The documentation stays true to the code: the generated reference pages (one per effect,
the effects' index, the built-in looks' table) match what ``python -m clfx.docsgen`` writes
now, the README stays a short page for a newcomer, and every relative link in README.md and
docs/ reaches an existing file and heading."""
import re
from pathlib import Path

from clfx import docsgen

ROOT = Path(__file__).resolve().parents[1]
README_MAX_LINES = 300
LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def test_generated_pages_are_up_to_date():
    stale = [str(p.relative_to(ROOT)) for p in docsgen.stale(ROOT)]
    orphans = [str(p.relative_to(ROOT)) for p in docsgen.orphans(ROOT)]
    assert not stale and not orphans, (
        f"generated docs are stale: {stale}; pages of no effect: {orphans}. "
        f"Regenerate with: PYTHONPATH=. python -m clfx.docsgen (from the repository root)")


def test_every_effect_has_a_page_listed_in_the_index():
    from clfx.plugins import discover

    index = (ROOT / "docs" / "effects" / "index.md").read_text()
    for name in discover():
        assert (ROOT / "docs" / "effects" / f"{name}.md").is_file(), name
        assert f"]({name}.md)" in index, name


def test_a_stale_page_is_found_and_hand_kept_notes_survive(tmp_path):
    """The check fails on an edited generated part, and regeneration keeps the hand-kept part."""
    (tmp_path / "docs" / "effects").mkdir(parents=True)
    bench = ROOT / docsgen.BENCH
    (tmp_path / docsgen.BENCH).write_text(bench.read_text())
    for path, text in docsgen.pages(ROOT).items():
        (tmp_path / path.relative_to(ROOT)).write_text(text)
    assert docsgen.stale(tmp_path) == []
    page = tmp_path / "docs" / "effects" / "vignette.md"
    page.write_text(page.read_text().replace("`natural`", "`naturel`") + "My note.\n")
    assert docsgen.stale(tmp_path) == [page]
    assert docsgen.main(["--check", "--root", str(tmp_path)]) == 1
    assert docsgen.main(["--root", str(tmp_path)]) == 0
    assert "`natural`" in page.read_text() and page.read_text().endswith("My note.\n")
    assert docsgen.main(["--check", "--root", str(tmp_path)]) == 0


def test_readme_is_short():
    n = len((ROOT / "README.md").read_text().splitlines())
    assert n <= README_MAX_LINES, (
        f"README.md has {n} lines (at most {README_MAX_LINES}): move reference material to docs/")


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip())
    text = text.lower().replace("`", "")
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    fence = False
    for line in path.read_text().splitlines():
        if line.startswith("```"):
            fence = not fence
        m = re.match(r"#{1,6}\s+(.*)", line)
        if m and not fence:
            base = slug(m.group(1))
            n = seen.get(base, 0)
            seen[base] = n + 1
            out.add(base if n == 0 else f"{base}-{n}")
    return out


def links(path: Path):
    fence = False
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        if line.startswith("```"):
            fence = not fence
            continue
        if fence:
            continue
        for target in LINK.findall(re.sub(r"`[^`]*`", "", line)):
            yield lineno, target


def broken_links(pages: list[Path], root: Path) -> list[str]:
    """``page:line: target (why)`` for each relative link that reaches no file or heading."""
    bad = []
    for page in pages:
        for lineno, target in links(page):
            if re.match(r"[a-z]+:", target):
                continue  # https:, mailto:
            file, _, anchor = target.partition("#")
            dest = (page.parent / file).resolve() if file else page
            where = f"{page.relative_to(root)}:{lineno}: {target}"
            if not dest.exists():
                bad.append(f"{where} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                bad.append(f"{where} (no heading #{anchor} in {dest.name})")
    return bad


def test_relative_links_reach_files_and_headings():
    bad = broken_links([ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))], ROOT)
    assert not bad, "broken links:\n" + "\n".join(bad)


def test_broken_links_are_found(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "a.md").write_text("# A page\n\n## Masks: per-object effects\n")
    readme = tmp_path / "README.md"
    readme.write_text("[ok](docs/a.md) [ok](docs/a.md#masks-per-object-effects) [ok](#top)\n"
                      "# Top\n`[not a link](nowhere.md)`\n[gone](docs/b.md) "
                      "[no anchor](docs/a.md#masks) [web](https://example.com/x.md)\n")
    bad = broken_links([readme], tmp_path)
    assert bad == ["README.md:4: docs/b.md (no such file)",
                   "README.md:4: docs/a.md#masks (no heading #masks in a.md)"], bad


def test_slugs_follow_github():
    assert slug("Masks: per-object effects") == "masks-per-object-effects"
    assert slug("`clfx bench`'s sequence table") == "clfx-benchs-sequence-table"
    assert slug("On a GPU: NVIDIA H100 through NVIDIA's OpenCL, beside PoCL") == \
        "on-a-gpu-nvidia-h100-through-nvidias-opencl-beside-pocl"
