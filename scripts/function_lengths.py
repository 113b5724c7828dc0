#!/usr/bin/env python3
"""The longest functions of the C++ sources (issue 34: none over 100 lines in sim/, fit/, python/
except declarative tables). Lengths from Universal Ctags (`ctags --fields=+ne`: each function's
first and last line), plus the pybind11 module body (PYBIND11_MODULE, a macro ctags does not see).

  /usr/bin/python3 scripts/function_lengths.py [--top N] [--over LINES] [DIR...]

Prints "lines  file:line  name", longest first; with --over, exits 1 when a function not in
ALLOWED is longer than LINES."""
import argparse
import json
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# Declarative tables: functions that are one list literal (a row per entry), not logic.
ALLOWED = {
}


def ctags_functions(paths):
    out = subprocess.run(["ctags", "-R", "--output-format=json", "--fields=+ne", "--languages=C++",
                          "--c++-kinds=f", "-o", "-", *paths], cwd=ROOT, check=True, capture_output=True,
                         text=True).stdout
    for line in out.splitlines():
        t = json.loads(line)
        if t.get("kind") == "function" and "end" in t:
            scope = t.get("scope", "")
            scope = "" if "__anon" in scope else scope.split("::")[-1]
            name = (scope + "::" if scope else "") + t["name"]
            yield t["end"] - t["line"] + 1, t["path"], t["line"], name


def module_bodies(paths):
    """PYBIND11_MODULE(...) { ... }: its length by brace matching (no braces in its strings assumed
    unbalanced)."""
    for top in paths:
        for dirpath, _, files in os.walk(os.path.join(ROOT, top)):
            for f in files:
                if not f.endswith((".cpp", ".hpp")):
                    continue
                p = os.path.join(dirpath, f)
                lines = open(p, encoding="utf-8").read().splitlines()
                for i, ln in enumerate(lines):
                    if re.match(r"\s*PYBIND11_MODULE\(", ln):
                        depth, started = 0, False
                        for j in range(i, len(lines)):
                            s = re.sub(r'"(\\.|[^"\\])*"', '""', lines[j])
                            depth += s.count("{") - s.count("}")
                            started = started or "{" in s
                            if started and depth == 0:
                                yield j - i + 1, os.path.relpath(p, ROOT), i + 1, "PYBIND11_MODULE"
                                break


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dirs", nargs="*", default=["sim", "fit", "python"])
    ap.add_argument("--top", type=int, default=20)
    ap.add_argument("--over", type=int, default=0)
    a = ap.parse_args()
    rows = sorted(set(ctags_functions(a.dirs)) | set(module_bodies(a.dirs)), key=lambda r: (-r[0], r[1], r[2]))
    for n, path, line, name in rows[:a.top]:
        mark = "  (table)" if name in ALLOWED.get(path, ()) else ""
        print(f"{n:5d}  {path}:{line}  {name}{mark}")
    if a.over:
        bad = [r for r in rows if r[0] > a.over and r[3] not in ALLOWED.get(r[1], ())]
        if bad:
            print(f"{len(bad)} functions over {a.over} lines", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
