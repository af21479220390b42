#!/usr/bin/env python3
"""Run every command and code sample of the README and the book (docs/), as scripts/docs.sh does.

    python scripts/docs/check_blocks.py [--update] [--jobs=N] [FILE.md ...]   # default: README.md and docs/**/*.md

Each Markdown file gets a scratch copy of the repository's `examples/` and `data/` (the shipped
campaign stores included, the cooling example's campaigns left out), and its blocks run there
in order, so a page's commands may build on each other but never on another page's or on the
checkout (which they leave as it was). By the block's language:

- `console`: every line `$ COMMAND` (continued by a trailing backslash) runs in bash and must
  exit 0; the lines after it are the output shown to the reader and are not compared;
- `sh`, `bash`, `shell`: every line that is not a comment runs the same way;
- `python`: the block runs as a script; where the next block is a `text` block marked
  `<!-- check: output -->` on the line above its fence, that block is the script's stdout and
  must equal it (`--update` rewrites it), except that a decimal number may differ from the one shown
  by round-off (one unit of its last shown digit, or 2 %): the GP fits' matrix kernels are
  chosen per CPU (AVX-512 or AVX2), which sum in another order, and a printed posterior std
  moves in its third digit between the two;
- `toml`, `json`: the block must parse (in TOML a line `…`, a comment after it allowed, stands
  for lines left out and is dropped first).

`{{#include path}}` (mdBook's include, relative to the page) is replaced by the file first.
`iuq` is `$IUQ_BIN` (default target/release/iuq), `python`/`python3` the interpreter running
this script, and `cargo run --release -p iuq --` is taken as `iuq` (the checker never builds);
any other `cargo` command must not run here.

A block that cannot run here (it needs Slurm, a server that runs until stopped, hours of
computing, or installs into the user's environment) is marked on the line just above its
fence, with the reason, and is then only parsed where its language allows:

    <!-- check: skip (needs a Slurm cluster) -->

`--update` writes each `console` command's real output (its stdout) under it in the page, in
place of what the page showed; an output the page trims with `…` is left as it is, and so is a
page whose commands failed.

`--jobs=N` checks N files at once (each in its own scratch copy).

Exit status 0 when every block passed, 1 otherwise.
"""

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SKIP = re.compile(r"^<!--\s*check:\s*skip\s*\((.+)\)\s*-->\s*$")
OUTPUT = re.compile(r"^<!--\s*check:\s*output\s*-->\s*$")
FENCE = re.compile(r"^(\s*)(`{3,}|~{3,})\s*([\w+-]*)")
INCLUDE = re.compile(r"\{\{#include\s+([^}\s]+)\s*\}\}")
RUN = {"console", "sh", "bash", "shell"}
TIMEOUT = 600


def blocks(path: Path):
    """(line number, language, text, skip reason or None) of each fenced block."""
    lines = path.read_text().split("\n")
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, fence, language = m.groups()
        previous = next((l for l in reversed(lines[:i]) if l.strip()), "")
        skip = SKIP.match(previous.strip())
        if OUTPUT.match(previous.strip()):
            language = "output"
        body = []
        j = i + 1
        while j < len(lines) and not lines[j].strip().startswith(fence):
            body.append(lines[j][len(indent):] if lines[j].startswith(indent) else lines[j])
            j += 1
        text = INCLUDE.sub(lambda inc: (path.parent / inc.group(1)).read_text(), "\n".join(body))
        yield i + 1, language.lower(), text, skip.group(1) if skip else None, j
        i = j + 1


def commands(language: str, text: str):
    """The commands of a console or shell block, continuation lines joined."""
    out, current = [], None
    for line in text.split("\n"):
        if current is not None:
            current += "\n" + line
        elif language == "console":
            if not line.startswith("$ "):
                continue
            current = line[2:]
        else:
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            current = line
        if not current.endswith("\\"):
            out.append(current)
            current = None
    if current is not None:
        out.append(current)
    return out


def sandbox(tmp: Path, iuq: str) -> dict:
    ignore = shutil.ignore_patterns("*.campaign.previous-*", "runs", "coordinator.lock", "*-report")
    shutil.copytree(ROOT / "examples", tmp / "examples", ignore=ignore)
    for campaign in (tmp / "examples" / "cooling").glob("*.campaign"):
        shutil.rmtree(campaign)
    shutil.copytree(ROOT / "data", tmp / "data")
    bin_dir = tmp / ".bin"
    bin_dir.mkdir()
    (bin_dir / "iuq").symlink_to(iuq)
    for name in ("python", "python3"):
        wrapper = bin_dir / name
        wrapper.write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
        wrapper.chmod(0o755)
    env = dict(os.environ, PATH=f"{bin_dir}{os.pathsep}{os.environ['PATH']}", MPLBACKEND="Agg")
    return env


NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


def same_output(shown: str, printed: str) -> bool:
    """The printed text equals the shown one, integers exactly and the other numbers within
    round-off of the shown ones (one unit of the last shown digit, or 2 % of the value)."""
    if NUMBER.split(shown) != NUMBER.split(printed):
        return False
    for a, b in zip(NUMBER.findall(shown), NUMBER.findall(printed)):
        if "." not in a:
            if a != b:
                return False
            continue
        unit = 10.0 ** -len(a.split(".")[1].split("e")[0].split("E")[0])
        x, y = float(a), float(b)
        if abs(x - y) > max(unit, 0.02 * max(abs(x), abs(y))) + 1e-12:
            return False
    return True


def shown_outputs(text: str):
    """The output lines the page shows under each `$` command of a console block."""
    outputs, current = [], None
    continuing = False
    for line in text.split("\n"):
        if continuing:
            continuing = line.endswith("\\")
            continue
        if line.startswith("$ "):
            current = []
            outputs.append(current)
            continuing = line.endswith("\\")
        elif current is not None:
            current.append(line)
    return outputs


def updated_console(text: str, stdouts) -> str:
    """The console block with each command's output replaced by ``stdouts`` (not where it is trimmed)."""
    shown = shown_outputs(text)
    out, k, continuing = [], -1, False
    for line in text.split("\n"):
        if continuing:
            out.append(line)
            continuing = line.endswith("\\")
            if not continuing and k < len(stdouts):
                out.extend(stdouts[k] if not any("…" in l for l in shown[k]) else shown[k])
            continue
        if line.startswith("$ "):
            k += 1
            out.append(line)
            continuing = line.endswith("\\")
            if not continuing:
                out.extend(stdouts[k] if not any("…" in l for l in shown[k]) else shown[k])
    return "\n".join(out)


def run_block(language, text, cwd, env, stdouts=None, say=print):
    """(ok, message) of one block; the stdout of each command is appended to ``stdouts``."""
    if language in RUN:
        for command in commands(language, text):
            command = re.sub(r"\bcargo run --release -p iuq --\s*", "iuq ", command)
            if re.match(r"\s*cargo\b", command):
                return False, f"`{command}`: cargo does not run in the docs check; mark the block"
            started = time.monotonic()
            p = subprocess.run(["bash", "-c", command], cwd=cwd, env=env, capture_output=True,
                               text=True, timeout=TIMEOUT)
            if p.returncode != 0:
                tail = (p.stderr or p.stdout).strip().splitlines()[-8:]
                return False, f"`{command}` exited with {p.returncode}:\n    " + "\n    ".join(tail)
            say(f"      $ {command.splitlines()[0][:90]}  ({time.monotonic() - started:.1f} s)")
            if stdouts is not None:
                stdouts.append(p.stdout.rstrip("\n").split("\n") if p.stdout.strip() else [])
        return True, ""
    if language == "python":
        script = cwd / ".block.py"
        script.write_text(text)
        p = subprocess.run([sys.executable, str(script)], cwd=cwd, env=env, capture_output=True,
                           text=True, timeout=TIMEOUT)
        if p.returncode != 0:
            return False, "the Python block failed:\n    " + "\n    ".join(p.stderr.strip().splitlines()[-8:])
        if stdouts is not None:
            stdouts.append(p.stdout.rstrip("\n"))
        return True, ""
    if language == "toml":
        text = "\n".join(l for l in text.split("\n") if l.split("#")[0].strip() != "…")
        try:
            tomllib.loads(text)
        except tomllib.TOMLDecodeError as e:
            return False, f"not valid TOML: {e}"
        return True, ""
    if language == "json":
        try:
            json.loads(text)
        except json.JSONDecodeError as e:
            return False, f"not valid JSON: {e}"
        return True, ""
    return True, ""


def check_file(path: Path, iuq: str, update: bool):
    """(log text, failures, blocks run, blocks not run) of one Markdown file."""
    log, failures, counted, skipped = [], [], 0, 0

    def say(text):
        log.append(text + "\n")

    found = list(blocks(path))
    edits = []
    checked = [b for b in found if b[1] in RUN | {"python", "toml", "json", "output"}]
    if not checked:
        return "", failures, counted, skipped
    last_python = None
    rel = path.relative_to(ROOT)
    say(f"{rel}")
    with tempfile.TemporaryDirectory(prefix="iuq-docs-check-") as tmp:
        env = sandbox(Path(tmp), iuq)
        for line, language, text, skip, end in checked:
            if language == "output":
                if last_python is None:
                    failures.append(f"{rel}:{line} (output): no Python block ran just before it")
                elif update:
                    edits.append((line, end, last_python))
                elif not same_output(text.rstrip("\n"), last_python):
                    failures.append(f"{rel}:{line} (output): the Python block above printed\n    "
                                    + "\n    ".join(last_python.split("\n")))
                else:
                    say(f"  {rel}:{line} output: as printed")
                last_python = None
                continue
            last_python = None
            if skip is not None:
                skipped += 1
                say(f"  {rel}:{line} {language}: not run ({skip})")
                ok, message = run_block(language, text, Path(tmp), env) if language in ("toml", "json") else (True, "")
            else:
                counted += 1
                started = time.monotonic()
                stdouts = [] if (update and language == "console") or language == "python" else None
                try:
                    ok, message = run_block(language, text, Path(tmp), env, stdouts, say)
                    if ok and language == "python":
                        last_python = stdouts[0]
                    elif ok and stdouts is not None:
                        edits.append((line, end, updated_console(text, stdouts)))
                except subprocess.TimeoutExpired as e:
                    ok, message = False, f"timed out after {e.timeout} s"
                say(f"  {rel}:{line} {language}: {'ok' if ok else 'FAILED'} ({time.monotonic() - started:.1f} s)")
            if not ok:
                failures.append(f"{rel}:{line} ({language}): {message}")
    if update and edits and not failures:
        lines = path.read_text().split("\n")
        for start, end, body in sorted(edits, reverse=True):
            lines[start:end] = body.split("\n")
        path.write_text("\n".join(lines))
        say(f"  {rel}: outputs updated")
    return "".join(log), failures, counted, skipped


def main() -> int:
    iuq = os.path.abspath(os.environ.get("IUQ_BIN", ROOT / "target/release/iuq"))
    if not os.access(iuq, os.X_OK):
        print(f"check_blocks: no iuq binary at {iuq} (set IUQ_BIN)", file=sys.stderr)
        return 1
    args = sys.argv[1:]
    update = "--update" in args
    args = [a for a in args if a != "--update"]
    options = [a for a in args if a.startswith("--")]
    args = [a for a in args if not a.startswith("--")]
    # The notebook's page (docs/notebooks/) is made by running the notebook: not run again.
    files = [Path(f).resolve() for f in args] or [ROOT / "README.md"] + sorted(
        p for p in (ROOT / "docs").rglob("*.md")
        if p.name != "SUMMARY.md" and "notebooks" not in p.relative_to(ROOT / "docs").parts)
    jobs = 1
    for a in options:
        if a.startswith("--jobs="):
            jobs = max(1, int(a.split("=", 1)[1]))
    results = []
    if jobs == 1:
        for path in files:
            results.append(check_file(path, iuq, update))
            print(results[-1][0], end="", flush=True)
    else:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(jobs) as pool:
            for result in pool.map(lambda p: check_file(p, iuq, update), files):
                results.append(result)
                print(result[0], end="", flush=True)
    failures = [f for r in results for f in r[1]]
    counted = sum(r[2] for r in results)
    skipped = sum(r[3] for r in results)
    print(f"check_blocks: {counted} blocks run or parsed, {skipped} marked not to run, {len(failures)} failed")
    for failure in failures:
        print(f"FAILED {failure}", file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
