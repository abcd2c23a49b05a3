"""The manual: README.md stays short, every relative link in README.md and docs/ reaches a file (and
an #anchor a heading there), and the MkDocs site builds with --strict, with a page per verb of the
parser that names each of its options."""

import glob
import os
import re
import subprocess
import unicodedata

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
MKDOCS = os.path.join(ROOT, ".venv", "bin", "mkdocs")

LINK = re.compile(r"(?<!!)\[(?:[^\]\\]|\\.)*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^(```|~~~).*?^\1", re.S | re.M)
CODE = re.compile(r"`[^`\n]*`")


def markdown_files() -> list[str]:
    return [os.path.join(ROOT, "README.md")] + sorted(
        glob.glob(os.path.join(ROOT, "docs", "**", "*.md"), recursive=True))


def slugify(text: str) -> str:
    """Python-Markdown's toc slugify (MkDocs' default): NFKD to ASCII, punctuation dropped, lowercase,
    runs of spaces and hyphens become one '-'."""
    text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    text = re.sub(r"[^\w\s-]", "", text).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def prose(text: str) -> str:
    """The text without code blocks and code spans (links are not read inside them)."""
    return CODE.sub("", FENCE.sub("", text))


def headings(path: str) -> set[str]:
    text = FENCE.sub("", open(path, encoding="utf-8").read())
    slugs = set()
    for m in re.finditer(r"^#{1,6}\s+(.*?)\s*#*\s*$", text, re.M):
        title = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", m.group(1))   # a link's text only
        slug, n = slugify(title.replace("`", "")), 1
        while slug in slugs:                                          # toc's de-duplication: x, x_1, x_2
            slug = f"{slugify(title.replace('`', ''))}_{n}"
            n += 1
        slugs.add(slug)
    return slugs


def relative_links(path: str) -> list[str]:
    out = []
    for target in LINK.findall(prose(open(path, encoding="utf-8").read())):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target) or target.startswith("//"):
            continue   # http:, https:, mailto: ...
        out.append(target)
    return out


def test_readme_is_at_most_250_lines():
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as f:
        n = sum(1 for _ in f)
    assert n <= 250, f"README.md has {n} lines: move text into docs/"


def test_readme_links_the_manual():
    links = relative_links(os.path.join(ROOT, "README.md"))
    for page in ("docs/guide/calibration.md", "docs/guide/daemon.md", "docs/guide/linuxcnc.md",
                 "docs/guide/arms.md", "docs/reference/machine-file.md"):
        assert page in links, page


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: os.path.relpath(p, ROOT))
def test_every_relative_link_reaches_a_file_and_heading(path):
    bad = []
    for target in relative_links(path):
        file_part, _, anchor = target.partition("#")
        dest = os.path.normpath(os.path.join(os.path.dirname(path), file_part)) if file_part else path
        rel_dest = os.path.relpath(dest, ROOT)
        generated = rel_dest.startswith(os.path.join("docs", "reference", "cli") + os.sep)
        if generated:
            continue   # written by docs/hooks/cli_reference.py at build time; the strict build checks them
        if not os.path.exists(dest):
            bad.append(f"{target}: no file {rel_dest}")
            continue
        if anchor and dest.endswith(".md") and anchor not in headings(dest):
            bad.append(f"{target}: no heading '#{anchor}' in {rel_dest}")
    assert not bad, f"{os.path.relpath(path, ROOT)}: " + "; ".join(bad)


def test_slugify_matches_the_toc_extension():
    toc = pytest.importorskip("markdown.extensions.toc")
    for title in ("Generated C++ and compensation", "Calibration workflow: protocol → identify → daemon",
                  "Machines outside configs/: models built at run time", "Circular test (ISO 230-4): ballbar traces"):
        assert slugify(title) == toc.slugify(title, "-")


@pytest.mark.slow
def test_mkdocs_build_strict_has_a_page_per_verb_with_every_option(tmp_path):
    if not os.path.exists(MKDOCS):
        pytest.skip(".venv/bin/mkdocs is missing: tools/setup installs docs/requirements.txt")
    site = tmp_path / "site"
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    proc = subprocess.run([MKDOCS, "build", "--strict", "--site-dir", str(site)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "WARNING" not in proc.stderr, proc.stderr

    import argparse
    from chaincomp.cli.main import build_parser
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    index = (site / "reference" / "cli" / "index.html").read_text(encoding="utf-8")
    for verb, parser in sub.choices.items():
        page = site / "reference" / "cli" / verb / "index.html"
        assert page.exists(), f"no page for 'chaincomp {verb}'"
        html = page.read_text(encoding="utf-8")
        assert f"chaincomp {verb}" in html
        assert f'href="{verb}/"' in index, f"the CLI index does not link {verb}"
        group = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        for action in parser._actions + [a for q in (group[0].choices.values() if group else []) for a in q._actions]:
            if action.help is argparse.SUPPRESS:
                continue
            for flag in action.option_strings:
                assert f"<code>{flag}</code>" in html, f"{verb}: {flag} missing from its page"
