"""Every bash and python code block of README.md and docs/*.md, executed as written.

The blocks run in one scratch copy of the repository (build/ linked in), in reading order:
README.md first, then docs/*.md alphabetically, each file's blocks top to bottom, so a block may
use what an earlier block made (docs/python.md reads the README's `runs/one`). A block that is not
meant to run here says so on the line just above it, with its reason:

    <!-- doc-test: long REASON -->      a long job (set-up, an ensemble of many packings, YADE):
                                        not run; its `build/dem` lines are checked against --help
    <!-- doc-test: synopsis REASON -->  a synopsis with placeholders (SCENE, DIR): not run; its
                                        `build/dem` lines are checked against --help

The executed blocks take about a minute (the README's one-packing run is most of it).
"""
import os
import re
import shlex
import shutil
import subprocess

import pytest

from conftest import DEM, ROOT

FENCE = re.compile(r"^```(\w*)\s*$")
MARK = re.compile(r"^<!--\s*doc-test:\s*(long|synopsis)\s+(\S.*?)\s*-->\s*$")
RUN_LANGS = {"bash", "sh", "python"}


def doc_files():
    docs = os.path.join(ROOT, "docs")
    return ["README.md"] + sorted(os.path.join("docs", f) for f in os.listdir(docs) if f.endswith(".md"))


def blocks(relpath):
    """(language, first line number, text, mark kind or None, mark reason) of each fenced block."""
    lines = open(os.path.join(ROOT, relpath), encoding="utf-8").read().splitlines()
    out, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m or not m.group(1):
            i += 1
            continue
        j = i + 1
        while j < len(lines) and not FENCE.match(lines[j]):
            j += 1
        prev = lines[i - 1] if i > 0 else ""
        mark = MARK.match(prev)
        out.append((m.group(1), i + 1, "\n".join(lines[i + 1:j]),
                    mark.group(1) if mark else None, mark.group(2) if mark else None))
        i = j + 1
    return out


ALL = [(f, *b) for f in doc_files() for b in blocks(f) if b[0] in RUN_LANGS]


def test_the_docs_have_runnable_blocks():
    """The extraction finds the blocks (a broken fence pattern would make every test below vacuous)."""
    assert sum(1 for b in ALL if b[4] is None) >= 4, ALL
    assert any(b[0] == "README.md" and b[1] == "python" for b in ALL)


def dem_lines(text):
    """The `build/dem SUB ...` commands of a block, comments and continuation lines joined."""
    joined = re.sub(r"\\\n\s*", " ", text)
    for line in joined.splitlines():
        line = line.split(" #", 1)[0].strip()
        for part in re.split(r"&&|;|\|", line):
            words = part.split()
            if "build/dem" in words and words.index("build/dem") + 1 < len(words):
                yield words[words.index("build/dem"):]


@pytest.mark.parametrize("path,lang,line,text,kind,reason",
                         [b for b in ALL if b[4] is not None], ids=lambda v: str(v)[:30])
def test_marked_block_options_exist(path, lang, line, text, kind, reason):
    """A block not run here still uses real subcommands and options: each `--option` of a
    `build/dem` line appears in that subcommand's --help."""
    assert len(reason) > 8, f"{path}:{line}: say why the block is not run"
    for words in dem_lines(text):
        sub = words[1]
        h = subprocess.run([DEM, sub, "--help"], capture_output=True, text=True, timeout=60)
        assert h.returncode == 0, f"{path}:{line}: `dem {sub} --help` failed: {h.stderr}"
        for w in words[2:]:
            if w.startswith("--"):
                opt = w.split("=", 1)[0]
                assert opt in h.stdout, f"{path}:{line}: `dem {sub}` has no option {opt}"


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    """A copy of the tracked files (as a fresh clone has them) with build/ linked in."""
    d = tmp_path_factory.mktemp("docblocks") / "repo"
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    for rel in filter(None, files.decode().split("\0")):
        src = os.path.join(ROOT, rel)
        if not os.path.isfile(src):
            continue   # deleted in the work tree
        dst = d / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(src, dst, follow_symlinks=False)
    os.symlink(os.path.join(ROOT, "build"), d / "build")
    return d


@pytest.mark.parametrize("path,lang,line,text,kind,reason",
                         [b for b in ALL if b[4] is None], ids=lambda v: str(v)[:30])
def test_block_runs_as_written(scratch, path, lang, line, text, kind, reason):
    env = dict(os.environ, OMP_WAIT_POLICY="passive", MPLBACKEND="Agg")
    env.pop("PYTHONPATH", None)   # the blocks say themselves where demtk is
    if lang == "python":
        # The README and docs/python.md state this once, in a comment above their blocks.
        env["PYTHONPATH"] = str(scratch / "build" / "python")
        cmd = ["/usr/bin/python3", "-c", text]
    else:
        cmd = ["bash", "-euo", "pipefail", "-c", text]
    p = subprocess.run(cmd, cwd=scratch, env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, (f"{path}:{line}: the {lang} block failed as written (exit {p.returncode}):\n"
                               f"{text}\n--- stdout\n{p.stdout[-2000:]}\n--- stderr\n{p.stderr[-3000:]}")
