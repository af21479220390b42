#!/usr/bin/env python3
"""mdBook preprocessor of iuq's book (book.toml, `[preprocessor.iuq]`), run by `mdbook build`.

Two rewrites of every chapter's Markdown, outside code blocks and code spans:

- **Math.** `$…$` (inline) and `$$…$$` (display, on lines of their own) hold LaTeX, as GitHub
  renders them in the Markdown sources; here they become MathML (latex2mathml), which browsers
  render without a script or a network connection.
  A page holding the comment `<!-- math: off -->` (the generated CLI reference) keeps its
  dollar signs as they are.
- **Links to repository files outside `docs/`** (`[text](../crates/…)`, `[text](../data/…)`):
  the book holds only `docs/`, so such a link would point nowhere in the built site. It becomes
  a link into the repository when `repository-url` is set in book.toml (e.g. a forge's
  `…/blob/main`), and otherwise the path itself as code (`data/hemocell_vs_native.md`).

The protocol: `mdbook` calls `… supports <renderer>` (exit 0: all renderers), then passes
`[context, book]` as JSON on stdin and reads the book back on stdout.
"""

import json
import posixpath
import re
import sys

from latex2mathml.converter import convert

FENCE = re.compile(r"^( {0,3})(`{3,}|~{3,})")
LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)\s]+)\)")
DISPLAY = re.compile(r"^\s*\$\$(.+?)\$\$\s*$")
INLINE = re.compile(r"(?<![\\$\w])\$(?=\S)([^$\n]+?)(?<=\S)\$(?![\w$])")
CODE_SPAN = re.compile(r"(`+)(.+?)\1", re.S)


def mathml(tex: str, display: bool) -> str:
    html = convert(tex.strip(), display="block" if display else "inline")
    return html.replace("\n", "")


def rewrite_text(text: str, chapter_dir: str, repo_url: str, math: bool = True) -> str:
    """Math and outside links in a run of Markdown text that holds no fenced block."""
    text = rewrite_links(text, chapter_dir, repo_url)
    if not math:
        return text
    out = []
    pos = 0
    for span in CODE_SPAN.finditer(text):
        out.append(INLINE.sub(lambda m: mathml(m.group(1), False), text[pos:span.start()]))
        out.append(span.group(0))
        pos = span.end()
    out.append(INLINE.sub(lambda m: mathml(m.group(1), False), text[pos:]))
    return "".join(out)


def rewrite_links(text: str, chapter_dir: str, repo_url: str) -> str:
    def link(m: "re.Match[str]") -> str:
        bang, label, target = m.groups()
        if bang or re.match(r"^[a-z][a-z0-9+.-]*:|^#|^/", target):
            return m.group(0)
        path, _, anchor = target.partition("#")
        resolved = posixpath.normpath(posixpath.join("docs", chapter_dir, path))
        if resolved.startswith("docs/") or resolved == "docs":
            return m.group(0)
        if repo_url:
            return f"[{label}]({repo_url.rstrip('/')}/{resolved}{'#' + anchor if anchor else ''})"
        code = f"`{resolved}`"
        return code if label.strip("`") == resolved else f"{label} ({code})"

    return LINK.sub(link, text)


def rewrite(content: str, chapter_dir: str, repo_url: str) -> str:
    math = "<!-- math: off -->" not in content
    lines = content.split("\n")
    out, plain, fence = [], [], None

    def flush():
        if plain:
            out.append(rewrite_text("\n".join(plain), chapter_dir, repo_url, math))
            plain.clear()

    i = 0
    while i < len(lines):
        line = lines[i]
        m = FENCE.match(line)
        if fence is None and m:
            flush()
            fence = m.group(2)[0] * len(m.group(2))
            out.append(line)
        elif fence is not None:
            out.append(line)
            if line.strip().startswith(fence) and line.strip().strip(fence[0]) == "":
                fence = None
        elif math and DISPLAY.match(line):
            flush()
            indent = line[: len(line) - len(line.lstrip())]
            out.append(indent + mathml(DISPLAY.match(line).group(1), True))
        elif math and line.strip() == "$$":
            # A display formula over several lines: up to the closing `$$`.
            flush()
            j = i + 1
            while j < len(lines) and lines[j].strip() != "$$":
                j += 1
            out.append(mathml(" ".join(lines[i + 1:j]), True))
            i = j
        else:
            plain.append(line)
        i += 1
    flush()
    return "\n".join(out)


def walk(items, repo_url):
    for item in items:
        chapter = item.get("Chapter") if isinstance(item, dict) else None
        if not chapter:
            continue
        source = chapter.get("source_path") or chapter.get("path") or ""
        chapter["content"] = rewrite(chapter["content"], posixpath.dirname(source), repo_url)
        walk(chapter.get("sub_items", []), repo_url)


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "supports":
        sys.exit(0)
    context, book = json.load(sys.stdin)
    settings = context.get("config", {}).get("preprocessor", {}).get("iuq", {})
    walk(book.get("items", book.get("sections", [])), settings.get("repository-url", ""))
    json.dump(book, sys.stdout)


if __name__ == "__main__":
    main()
