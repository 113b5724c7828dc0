"""Reading the curve CSVs written by `dem run` and by the YADE scripts in yade_ref/.

A curve file has '#' comment lines (units, definitions), one header line, then rows.
"""
import csv
import os
import stat
import numpy as np

# Columns every curve file carries (same names in our runner and in yade_ref/).
REQUIRED_COLUMNS = (
    "step", "time_s", "eps_xx", "eps_yy", "eps_zz", "eps_v", "eps_d", "nu", "p_Pa", "p_star",
    "sigma_xx_Pa", "sigma_yy_Pa", "sigma_zz_Pa", "sigma_xy_Pa", "sigma_xz_Pa", "sigma_yz_Pa",
    "sigma_dev_Pa", "s_dev", "F_xx", "F_yy", "F_zz", "F_xy", "F_xz", "F_yz", "F_dev", "C",
    "C_nonrattler", "rattler_fraction", "E_kin_J", "overlap_max_rel", "overlap_mean_rel")


class CurveError(ValueError):
    """A curve file is missing, malformed, or lacks a column."""


def read_text(path):
    """(comment lines, header, rows) of a curve CSV, the cells as text: the one reader of the format
    (read_curve, demkit.path_ensemble and the benchmarks use it). Comment lines keep their '#' and
    lose their line end. Raises CurveError naming the file and the problem."""
    try:
        # a regular file only: a device (/dev/zero) or a FIFO would never end (opened without blocking)
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            raise CurveError(f"{path} is not a regular file (a device, FIFO or folder): give a curve CSV")
        os.set_blocking(fd, True)
        with open(fd, newline="") as fh:
            text = fh.read().splitlines()
    except OSError as e:
        raise CurveError(f"cannot read curve file {path}: {e.strerror}") from None
    comments = [ln for ln in text if ln.startswith("#")]
    lines = [ln for ln in text if ln.strip() and not ln.startswith("#")]
    if not lines:
        raise CurveError(f"{path}: no header line (empty or comments only)")
    rows = list(csv.reader(lines))
    header, data = rows[0], rows[1:]
    for i, r in enumerate(data):
        if len(r) != len(header):
            raise CurveError(f"{path}: data row {i + 1} has {len(r)} cells, header has {len(header)}")
    return comments, header, data


def read_curve(path):
    """Return a dict column name -> numpy array (float; non-numeric columns as str arrays).

    Raises CurveError naming the file and the problem.
    """
    _, header, data = read_text(path)
    out = {}
    for k, name in enumerate(header):
        col = [r[k] for r in data]
        try:
            out[name] = np.array([float(v) for v in col])
        except ValueError:
            out[name] = np.array(col)
    return out


def require(curve, names, path="curve"):
    missing = [n for n in names if n not in curve]
    if missing:
        raise CurveError(f"{path}: missing column(s) {', '.join(missing)}")
