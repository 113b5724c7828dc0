#!/usr/bin/env python3
"""The include graph of the engine library's folders (sim/src/X, sim/include/dem/X) and the
layering ARCHITECTURE.md draws (issue 34): no folder includes a higher one, and a header private
to one folder (sim/src/X/*.hpp) is read only from that folder.

  /usr/bin/python3 scripts/include_graph.py            # the quoted #include lines of the sources
  /usr/bin/python3 scripts/include_graph.py --deps build   # the compiler's own dependency files
                                                           # (build/sim/**/*.o.d, from -MD)
  /usr/bin/python3 scripts/include_graph.py --dot       # the folder graph for Graphviz

Prints the folder edges with their counts and every arrow against the layering; exits 1 if any.
The dependency files list every header a file reads, directly or not, so with --deps an arrow
names the file and the header at its end."""
import argparse
import glob
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# Lowest first: a folder may include only folders before it (and itself).
LAYERS = ["core", "contact", "forces", "measure", "engine", "io", "stages", "cli"]


def folder_of(path):
    """The layer of a file under sim/ (or None: outside the library, e.g. common/ or a system header)."""
    p = os.path.relpath(os.path.realpath(path), ROOT).replace(os.sep, "/")
    m = re.match(r"sim/(?:src|include/dem)/([a-z_]+)/", p)
    return (m.group(1), p) if m and m.group(1) in LAYERS else (None, p)


def source_files():
    return sorted(glob.glob(os.path.join(ROOT, "sim/src/*/*.?pp")) +
                  glob.glob(os.path.join(ROOT, "sim/include/dem/*/*.hpp")))


def quoted_includes():
    """(file, header) for each `#include "..."`, resolved as the build does (-I sim/include, -I sim/src)."""
    for f in source_files():
        for line in open(f, encoding="utf-8"):
            m = re.match(r'\s*#\s*include\s+"([^"]+)"', line)
            if not m:
                continue
            inc = m.group(1)
            for base in ("sim/include", "sim/src", os.path.relpath(os.path.dirname(f), ROOT)):
                cand = os.path.join(ROOT, base, inc)
                if os.path.exists(cand):
                    yield f, cand
                    break


def dependency_files(build):
    """(source, header) for every header in the compiler's .d files of the library and the CLI
    (paths relative to the folder make ran the compiler in: build/ or build/sim/)."""
    def resolve(name):
        if os.path.isabs(name):
            return name
        for base in (os.path.join(build, "sim"), build):
            cand = os.path.normpath(os.path.join(base, name))
            if os.path.exists(cand):
                return cand
        return None
    for d in glob.glob(os.path.join(build, "**", "*.o.d"), recursive=True):
        if "/sim/src/" not in d.replace(os.sep, "/") and "/src/" not in d.replace(os.sep, "/"):
            continue
        text = open(d, encoding="utf-8").read().replace("\\\n", " ")
        _, _, deps = text.partition(": ")
        names = deps.split()
        src = resolve(names[0]) if names else None
        if not src:
            continue
        for h in names[1:]:
            h = resolve(h)
            if h:
                yield src, h


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--deps", metavar="BUILD", help="read the compiler's dependency files of this build folder")
    ap.add_argument("--dot", action="store_true", help="print the folder graph in Graphviz's dot language")
    a = ap.parse_args()
    pairs = dependency_files(os.path.abspath(a.deps)) if a.deps else quoted_includes()
    edges, bad = {}, []
    for f, h in pairs:
        (src, fp), (dst, hp) = folder_of(f), folder_of(h)
        if src is None or dst is None or src == dst:
            continue
        edges[(src, dst)] = edges.get((src, dst), 0) + 1
        if LAYERS.index(dst) > LAYERS.index(src):
            bad.append(f"{fp} -> {hp}: {src}/ includes the higher {dst}/")
        if hp.startswith("sim/src/"):
            bad.append(f"{fp} -> {hp}: a header private to {dst}/ read from {src}/")
    if a.dot:
        print("digraph layers {\n  rankdir=BT;")
        for (s, d), n in sorted(edges.items()):
            up = LAYERS.index(d) > LAYERS.index(s)
            print(f'  {s} -> {d} [label="{n}"{", color=red" if up else ""}];')
        print("}")
    else:
        print("layers, lowest first: " + " < ".join(LAYERS))
        for (s, d), n in sorted(edges.items(), key=lambda e: (LAYERS.index(e[0][0]), LAYERS.index(e[0][1]))):
            print(f"  {s:8s} -> {d:8s} {n:4d}" + ("   AGAINST THE LAYERING" if LAYERS.index(d) > LAYERS.index(s) else ""))
    for b in sorted(set(bad)):
        print("include_graph: " + b, file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
