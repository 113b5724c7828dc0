"""The one atomic writer of demkit (the C++ side has dem::write_file_atomic, common/atomic_file.hpp):
write PATH.part, created exclusively (a stale .part or a planted symbolic link is unlinked, never
followed), flush and fsync, then rename onto PATH, so a reader never sees half a file and a file
that exists is complete. Every error propagates (a full disk leaves only the .part).
"""
import json
import math
import os
import sys


def open_exclusive(tmp, mode="w", newline=None):
    """A temporary file created exclusively: whatever is at `tmp` is unlinked first, and
    O_EXCL | O_NOFOLLOW never follow a link."""
    try:
        os.unlink(tmp)
    except FileNotFoundError:
        pass
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
    return os.fdopen(fd, mode, newline=newline)


def write_atomic(path, data):
    """Write str or bytes to `path` atomically (its folder is created if needed)."""
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    tmp = path + ".part"
    with open_exclusive(tmp, "wb" if isinstance(data, (bytes, bytearray)) else "w") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def write_md_csv(out, stem, md, lines, show=True):
    """OUT/STEM.md (MD: its lines) and OUT/STEM.csv (LINES: each ending in a newline), each written atomically; the
    markdown printed unless show=False (the tables of demkit's model_* scripts)."""
    write_atomic(os.path.join(out, f"{stem}.md"), "\n".join(md) + "\n")
    write_atomic(os.path.join(out, f"{stem}.csv"), "".join(lines))
    if show:
        print("\n".join(md))


def write_figure(fig, stem, exts=("png", "svg"), dpi=120, metadata=None, close=True):
    """stem.EXT for each of exts, each rendered in memory and written atomically (a failed or
    interrupted save leaves the previous file, never half a figure). metadata: {ext: dict} passed
    to savefig (PNG text chunks, SVG Dublin Core). Closes the figure unless close=False."""
    import io
    for ext in exts:
        buf = io.BytesIO()
        kw = {"metadata": metadata[ext]} if metadata and ext in metadata else {}
        fig.savefig(buf, format=ext, dpi=dpi, **kw)
        write_atomic(f"{stem}.{ext}", buf.getvalue())
    if close:
        import matplotlib.pyplot as plt
        plt.close(fig)


def write_json_atomic(path, obj, indent=1):
    """JSON of `obj`; NaN and infinities become null (they are not JSON numbers)."""
    write_atomic(path, json.dumps(finite_or_null(obj), indent=indent, allow_nan=False) + "\n")


def finite_or_null(obj):
    """obj with every non-finite float (and numpy number) replaced by None, for strict JSON."""
    np = sys.modules.get("numpy")   # numpy values come with numpy imported: the workflow's task
    if isinstance(obj, dict):       # wrapper never pays numpy's import
        return {k: finite_or_null(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite_or_null(v) for v in obj]
    if np is not None:
        if isinstance(obj, np.ndarray):
            return finite_or_null(obj.tolist())
        if isinstance(obj, np.bool_):
            return bool(obj)
        if isinstance(obj, np.floating):
            obj = float(obj)
        elif isinstance(obj, np.integer):
            return int(obj)
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
