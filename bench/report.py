"""Writing the Markdown result pages and figures of the benchmark scripts (atomically, through
demkit.atomic: an interrupted script leaves the previous page or figure, never half of one)."""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from demkit.atomic import write_atomic, write_figure  # noqa: E402


def write_markdown(path, lines, notes_path=None):
    """Writes lines (plus the hand-written notes file, when it exists) to path and prints them."""
    if notes_path and os.path.exists(notes_path):
        with open(notes_path) as fh:
            lines = lines + ["", fh.read()]
    write_atomic(path, "\n".join(lines) + "\n")
    print("\n".join(lines))


def save_figure(fig, stem, exts=("png", "svg"), dpi=120):
    """stem.png and stem.svg (or exts), each written atomically; closes the figure."""
    write_figure(fig, stem, exts=exts, dpi=dpi)
