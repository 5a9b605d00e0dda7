"""The Python examples in README.md and docs/*.md run as written.

Each file's ```python blocks run in order in one fresh interpreter, sharing one namespace as a
reader's session would (README's second block uses the first's import), in an empty folder that
holds a link to examples/ (what the examples load). A block that cannot run here is marked in the
Markdown on the line just above its fence:

    <!-- example: skip: why it cannot run in a test, and which test covers what it calls -->

Everything else must run without an exception; a failure names the file and the block's line.
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from _optional import missing, missing_povray, require

ROOT = Path(__file__).resolve().parents[2]
FILES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```python\n(.*?)^```", re.S | re.M)
SKIP = re.compile(r"<!-- example: skip: (.+?) -->\s*$")


def _viewer_missing():
    from flagsim import viewer

    return missing("polyscope", "viewer") or viewer.probe_headless()


# What a file's examples need beyond flagsim: skipped here without it, failed under CI (_optional).
NEEDS = {
    "rendering.md": [missing_povray],
    "viewer.md": [_viewer_missing, lambda: missing("pxr", "usd")],
}

# Runs the blocks given as JSON on stdin: [[line, source], ...]; stops at the first failure.
RUNNER = """
import json, sys, traceback
blocks = json.load(sys.stdin)
ns = {"__name__": "__main__"}
for line, source in blocks:
    try:
        exec(compile(source, f"{sys.argv[1]}:{line}", "exec"), ns)
    except BaseException:
        traceback.print_exc()
        print(f"EXAMPLE FAILED: {sys.argv[1]}, the block at line {line}", file=sys.stderr)
        sys.exit(1)
"""


def blocks(path: Path) -> tuple[list[tuple[int, str]], list[tuple[int, str]]]:
    """(blocks to run, blocks skipped) of one Markdown file: (line of the fence, source) and
    (line of the fence, the reason given)."""
    text = path.read_text()
    run, skipped = [], []
    for m in FENCE.finditer(text):
        line = text.count("\n", 0, m.start()) + 1
        before = text[: m.start()].rstrip("\n").rsplit("\n", 1)[-1]
        why = SKIP.search(before)
        if why:
            skipped.append((line, why.group(1)))
        else:
            run.append((line, m.group(1)))
    return run, skipped


def test_every_skip_marker_sits_above_a_python_block():
    """A marker that lost its block (the block moved or changed language) would skip nothing
    silently; a marker's reason must say something."""
    for path in FILES:
        text = path.read_text()
        markers = [m for m in re.finditer(r"<!-- example: skip:(.*?)-->", text)]
        for m in markers:
            after = text[m.end() :].lstrip(" \t").split("\n", 2)
            assert after[0] == "" and after[1] == "```python", (
                f"{path.name}: the skip marker at offset {m.start()} is not on the line just "
                "above a ```python fence"
            )
            assert len(m.group(1).strip()) > 20, f"{path.name}: a skip marker without a reason"


@pytest.mark.parametrize("path", [p for p in FILES if blocks(p)[0]], ids=lambda p: p.name)
def test_examples_run(path, tmp_path):
    for why in NEEDS.get(path.name, []):
        require(why())
    run, _ = blocks(path)
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    import json

    env = dict(os.environ, MPLBACKEND="Agg")
    res = subprocess.run(
        [sys.executable, "-c", RUNNER, str(path.relative_to(ROOT))],
        input=json.dumps(run),
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 0, res.stderr[-4000:]


def test_the_docs_have_examples_and_few_skips():
    """The collection itself: if the fence pattern stopped matching, every example test above
    would pass by running nothing."""
    ran = sum(len(blocks(p)[0]) for p in FILES)
    skipped = sum(len(blocks(p)[1]) for p in FILES)
    assert ran >= 15, f"only {ran} ```python blocks found in README.md and docs/"
    assert skipped <= 3, f"{skipped} examples are marked skip: run them or say why in the docs"


def command_lines() -> list[tuple[str, int, str]]:
    """(file, line, command) of every `flagsim ...` line in the docs' shell blocks (continuation
    lines joined; usage templates with [optional] parts left out)."""
    out = []
    for path in FILES:
        text = path.read_text()
        for m in re.finditer(r"^```(?:sh|bash|console)\n(.*?)^```", text, re.S | re.M):
            first = text.count("\n", 0, m.start()) + 2
            lines = m.group(1).split("\n")
            k = 0
            while k < len(lines):
                start, line = k, lines[k]
                while line.endswith("\\") and k + 1 < len(lines):
                    k += 1
                    line = line[:-1] + " " + lines[k]
                k += 1
                if line.startswith("flagsim ") and "[--" not in line:
                    out.append((path.name, first + start, line))
    return out


def test_every_documented_command_line_parses():
    """Each `flagsim COMMAND ...` shown in README.md and docs/ is accepted by that command's
    parser as written: an option renamed or removed fails here, not in a user's shell."""
    import shlex

    from flagsim import cli

    lines = command_lines()
    assert len(lines) >= 20, f"only {len(lines)} command lines found in the docs' shell blocks"
    for name, line, command in lines:
        argv = shlex.split(command, comments=True)[1:]
        assert argv[0] in cli.COMMANDS, f"{name}:{line}: unknown command in {command!r}"
        _, parser = cli.command_parser(argv[0])
        try:
            parser.parse_args(argv[1:])
        except SystemExit as e:
            pytest.fail(f"{name}:{line}: {command!r} does not parse (exit {e.code})")
