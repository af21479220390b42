#!/usr/bin/env python3
"""Check every relative link and anchor of the Markdown sources and of the built site (no network).

    python scripts/docs/check_links.py [--site book]

Sources: README.md, CONTRIBUTING.md, CHANGELOG.md, docs/**/*.md, python/README.md and the
examples' README.md and PROVENANCE.md files. A relative link must name a file or folder of the
repository, and an anchor (`file.md#anchor`, `#anchor`) a heading of that Markdown file, by
GitHub's rule for heading anchors. Links to `.html` pages exist only in the built site and are
checked there.

Site (`--site DIR`, the book built by mdBook with the Python API reference inside): every
`href` and `src` that is not absolute (`http:`, `https:`, `mailto:`, `data:`, …) must name a
file of the site, and its anchor an `id` (or `name`) in that page.

Links to other sites are not followed. Exit status 0 when every link resolves, 1 otherwise.
"""

import argparse
import re
import sys
import unicodedata
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

ROOT = Path(__file__).resolve().parents[2]
FENCE = re.compile(r"^\s*(`{3,}|~{3,})")
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")


def sources():
    files = [ROOT / "README.md", ROOT / "CONTRIBUTING.md", ROOT / "CHANGELOG.md", ROOT / "python/README.md"]
    files += sorted((ROOT / "docs").rglob("*.md"))
    files += sorted((ROOT / "examples").rglob("README.md")) + sorted((ROOT / "examples").rglob("PROVENANCE.md"))
    return [f for f in files if f.is_file()]


def prose(text: str):
    """(line number, line) outside fenced blocks, with code spans blanked out."""
    fence = None
    for number, line in enumerate(text.split("\n"), 1):
        m = FENCE.match(line)
        if m:
            if fence is None:
                fence = m.group(1)[0] * len(m.group(1))
            elif line.strip().startswith(fence):
                fence = None
            continue
        if fence is None:
            yield number, re.sub(r"(`+)(?:(?!\1).)+\1", lambda s: " " * len(s.group(0)), line)


def github_slug(heading: str) -> str:
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)     # links: their text
    text = re.sub(r"<[^>]+>", "", text).replace("`", "")
    text = text.strip().lower()
    out = []
    for ch in text:
        if ch in "-_" or ch.isalnum() or unicodedata.category(ch).startswith("M"):
            out.append(ch)
        elif ch == " ":
            out.append("-")
    return "".join(out)


_anchors = {}


def anchors_of(path: Path):
    if path not in _anchors:
        seen, found = {}, set()
        fence = None
        for line in path.read_text().split("\n"):
            m = FENCE.match(line)
            if m:
                fence = None if fence else True
                continue
            if fence:
                continue
            h = HEADING.match(line)
            if h:
                slug = github_slug(h.group(2))
                n = seen.get(slug, 0)
                seen[slug] = n + 1
                found.add(slug if n == 0 else f"{slug}-{n}")
            for explicit in re.findall(r'<a\s+(?:id|name)="([^"]+)"', line):
                found.add(explicit)
        _anchors[path] = found
    return _anchors[path]


def check_sources():
    errors = []
    for path in sources():
        text = path.read_text()
        for number, line in prose(text):
            for target in LINK.findall(line):
                if SCHEME.match(target) or target.startswith("//"):
                    continue
                file_part, _, anchor = target.partition("#")
                file_part = unquote(file_part)
                where = f"{path.relative_to(ROOT)}:{number}"
                if file_part.endswith(".html"):
                    continue            # a page of the built site: checked there
                dest = path if not file_part else (path.parent / file_part).resolve()
                if file_part and not dest.exists():
                    errors.append(f"{where}: {target}: no such file")
                    continue
                try:
                    dest.relative_to(ROOT)
                except ValueError:
                    errors.append(f"{where}: {target}: outside the repository")
                    continue
                if anchor and dest.suffix == ".md" and anchor not in anchors_of(dest):
                    errors.append(f"{where}: {target}: no heading with the anchor #{anchor}")
    return errors


class Page(HTMLParser):
    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.ids, self.links = set(), []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        for key in ("id", "name"):
            if attrs.get(key) and (key == "id" or tag == "a"):
                self.ids.add(attrs[key])
        for key in ("href", "src"):
            if attrs.get(key) is not None and tag != "base":
                self.links.append((self.getpos()[0], attrs[key]))


def check_site(site: Path):
    errors, pages = [], {}
    for html in sorted(site.rglob("*.html")):
        page = Page()
        page.feed(html.read_text(errors="replace"))
        pages[html.resolve()] = page
    for html, page in pages.items():
        for line, target in page.links:
            if not target or SCHEME.match(target) or target.startswith("/"):
                continue            # another site, or the site's root (404.html)
            parts = urlsplit(target)
            where = f"{html.relative_to(site.resolve())}:{line}"
            dest = html if not parts.path else (html.parent / unquote(parts.path)).resolve()
            if dest.is_dir():
                dest = dest / "index.html"
            if not dest.exists():
                errors.append(f"{where}: {target}: no such file in the site")
                continue
            try:
                dest.relative_to(site.resolve())
            except ValueError:
                errors.append(f"{where}: {target}: outside the site")
                continue
            if parts.fragment and dest.suffix == ".html":
                target_page = pages.get(dest)
                if target_page is not None and unquote(parts.fragment) not in target_page.ids:
                    errors.append(f"{where}: {target}: no element with the id #{parts.fragment}")
    return errors, len(pages)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", help="the built site to check as well (e.g. book)")
    args = parser.parse_args()
    errors = check_sources()
    n_sources = len(sources())
    summary = f"check_links: {n_sources} Markdown files"
    if args.site:
        site_errors, n_pages = check_site(Path(args.site))
        errors += site_errors
        summary += f", {n_pages} pages of {args.site}"
    for error in errors:
        print(f"broken link: {error}", file=sys.stderr)
    print(f"{summary}: {len(errors)} broken links")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
