"""Writing the Markdown result pages of the benchmark scripts."""
import os


def write_markdown(path, lines, notes_path=None):
    """Writes lines (plus the hand-written notes file, when it exists) to path and prints them."""
    if notes_path and os.path.exists(notes_path):
        with open(notes_path) as fh:
            lines = lines + ["", fh.read()]
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("\n".join(lines))
