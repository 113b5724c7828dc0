"""The summary of a parameter sweep: the fitted parameters of every row's ensemble against the
swept keys, as a table and as figures.

    python3 -m demkit.sweep DIR        (the workflow's last task; DIR holds sweep.json and rows/NAME/)

Reads DIR/sweep.json (written by `dem ensemble SCENE --sweep TABLE` or a scene's [sweep]) and
each row's DIR/rows/NAME/fit/parameters.csv (`dem fit` on that row's ensemble folder); writes
  DIR/sweep/parameters.csv    one line per (row, mode, nu, quantity): the swept values, then the fit
                              (x_max, beta, their standard errors and 95 % intervals, R^2, warnings);
                              units: a scene key's unit is in its name (stiffness_N_m, *_tc in
                              units of t_c); x0, x_max, beta and R^2 are dimensionless
  DIR/sweep/parameters.json   the same rows (NaN and infinities as null)
  DIR/sweep/parameters.md     the table for people: values rounded to their errors, warnings as footnotes
  DIR/sweep/parameters_KEY.{png,svg}   x_max and beta against each numeric swept key, one series per
                              (mode, nu), 95 % intervals as bars (demkit.figures conventions)
"""
import argparse
import csv
import io
import json
import os
import re
import sys

import numpy as np

from demkit.atomic import write_atomic, write_json_atomic
from demkit.figures import legend_if_any, not_usable_because, parameter_label, save, usable
from demkit.plots import paren

FIT_COLUMNS = ["packings", "x0", "se_x0", "x_max", "se_x_max", "x_max_lo95", "x_max_hi95", "beta", "se_beta",
               "beta_lo95", "beta_hi95", "initial_slope", "se_initial_slope", "r_squared", "error_method", "warnings",
               "usable", "not_usable_because"]

# Scene keys as a paper writes them; others: the key, with the unit its name carries.
KEY_LABEL = {"contact.friction": r"friction coefficient $\mu$", "contact.stiffness_N_m": r"stiffness $k$ [N/m]",
             "contact.damping_kg_s": r"normal damping $\gamma$ [kg/s]",
             "contact.background_damping_kg_s": r"background damping $\gamma_b$ [kg/s]",
             "contact.tangential_stiffness_ratio": r"$k_t/k$", "contact.rolling_friction": r"rolling friction $\mu_r$",
             "protocol.deviatoric_rate_tc": r"deviatoric rate $\dot\varepsilon_d\,t_c$",
             "integration.dt_over_tc": r"time step $\Delta t/t_c$", "particles.count": r"particles $N$"}
UNITS = [("_N_m", "N/m"), ("_kg_s", "kg/s"), ("_kg_m3", "kg/m$^3$"), ("_Pa", "Pa"), ("_m", "m"), ("_tc", "units of $t_c$")]


def key_label(key):
    if key in KEY_LABEL:
        return KEY_LABEL[key]
    for suffix, unit in UNITS:
        if key.endswith(suffix):
            return f"{key} [{unit}]"
    return key


def number(text):
    """A swept value as a float when it is one (TOML number text), else None."""
    try:
        v = float(text.replace("_", ""))
    except (AttributeError, ValueError):
        return None
    return v if np.isfinite(v) else None


def fnum(r, k):
    try:
        return float(r.get(k) or "nan")
    except ValueError:
        return float("nan")


def read_sweep(out):
    path = os.path.join(out, "sweep.json")
    if not os.path.exists(path):
        sys.exit(f"demkit.sweep: {out} has no sweep.json: it is not a sweep folder (run `dem ensemble SCENE --sweep "
                 "TABLE --out DIR`)")
    with open(path) as fh:
        return json.load(fh)


def collect(out, sweep):
    """One dict per (row, mode, nu, quantity) of every row's fit table, with the row's swept values."""
    rows, missing = [], []
    for r in sweep["rows"]:
        table = os.path.join(out, r["folder"], "fit", "parameters.csv")
        if not os.path.exists(table):
            missing.append(r["name"])
            continue
        with open(table, newline="") as fh:
            for fit in csv.DictReader(fh):
                row = {"row": r["name"], **{k: r["values"][k] for k in sweep["keys"]}}
                row.update({k: fit.get(k, "") for k in ("mode", "nu", "quantity")})
                row.update({k: fit.get(k, "") for k in FIT_COLUMNS})
                rows.append(row)
    if missing:
        sys.exit(f"demkit.sweep: rows without fit tables ({', '.join(missing)}): finish them first "
                 f"(`dem ensemble` on the sweep continues where it stopped)")
    return rows


def csv_text(rows, header):
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=header, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def markdown(rows, sweep):
    """Rows rounded to their errors (0.197(2)); warnings as footnote marks below the table."""
    keys = sweep["keys"]
    notes = {}
    head = ["row", *[f"`{k}`" for k in keys], "mode", "ν", "quantity", "K", "x<sub>max</sub>", "β", "R²"]
    lines = [f"**Parameter sweep: the saturating law fitted to each row's ensemble (dem fit), against "
             f"{', '.join(keys)}; errors between packings (jackknife)**", "",
             "| " + " | ".join(head) + " |", "|" + ":--|" * (1 + len(keys)) + ":--|--:|:--|--:|--:|--:|--:|"]
    for r in rows:
        marks = []
        why = not_usable_because(r)
        for w in ([f"not usable: {why}"] if why else []) + [w.strip() for w in r["warnings"].split(";") if w.strip()]:
            notes.setdefault(w, chr(ord("a") + len(notes)) if len(notes) < 26 else str(len(notes) + 1))
            marks.append(notes[w])
        q = r["quantity"].replace("_dev", "<sub>dev</sub>")
        q += f" <sup>{','.join(marks)}</sup>" if marks else ""
        values = ([paren(fnum(r, "x_max"), fnum(r, "se_x_max")), paren(fnum(r, "beta"), fnum(r, "se_beta")),
                   f"{fnum(r, 'r_squared'):.3f}"] if not why else ["not usable", "", ""])
        lines.append("| " + " | ".join([r["row"], *[r[k] for k in keys], r["mode"], r["nu"], q, r["packings"],
                                         *values]) + " |")
    lines += ["", "Each value is rounded to its standard error, in parentheses in units of the last digit "
                  "(0.197(2) = 0.197 ± 0.002). K: packings. x<sub>max</sub>, β, R² are dimensionless; a swept key's "
                  "unit is in its name. Every digit: parameters.csv / parameters.json; each row's own tables: "
                  "rows/NAME/fit/.", ""]
    lines += [f"<sup>{m}</sup> {w}  " for w, m in notes.items()]
    return "\n".join(lines) + "\n"


def series(rows):
    """{(mode, nu): [rows]} in a stable order."""
    out = {}
    for r in sorted(rows, key=lambda r: (r["mode"], fnum(r, "nu"))):
        out.setdefault((r["mode"], r["nu"]), []).append(r)
    return out


def plot_against(out, rows, sweep, key):
    """x_max and beta of s_dev and F_dev against one swept key: a panel only where some (mode, nu)
    has two or more finite values (others are left out, and the figure says so)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    xs = {r["row"]: number(r[key]) for r in rows}
    panels, left_out = [], []
    for q in ("s_dev", "F_dev"):
        for par in ("x_max", "beta"):
            sel = [r for r in rows if r["quantity"] == q and np.isfinite(fnum(r, par))]
            if any(len({xs[r["row"]] for r in s}) >= 2 for s in series(sel).values()):
                panels.append((q, par, sel))
            else:
                left_out.append(parameter_label(par, q).split(" (")[0])
    if not panels:
        print(f"demkit.sweep: note: no figure against {key}: no parameter was fitted at two or more of its values",
              file=sys.stderr)
        return None
    ncols = 2 if len(panels) > 1 else 1
    nrows = (len(panels) + 1) // 2
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.6 * ncols, 3.4 * nrows), squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    undetermined = False
    for ax, (q, par, sel) in zip(axes.flat, panels):
        for i, ((mode, nu), s) in enumerate(series(sel).items()):
            s = sorted(s, key=lambda r: xs[r["row"]])
            x = np.array([xs[r["row"]] for r in s])
            v = np.array([fnum(r, par) for r in s])
            lo = np.array([fnum(r, f"{par}_lo95") for r in s])
            hi = np.array([fnum(r, f"{par}_hi95") for r in s])
            # as in demkit.figures: a fit that is not usable (the tables' rule) is no result: a hollow
            # marker without its bar
            ok = np.array([usable(r) for r in s]) & np.isfinite(lo) & np.isfinite(hi)
            colour, label = colours[i % len(colours)], rf"{mode}, $\nu$ = {float(nu):.3g}"
            ax.plot(x, v, "-" if mode == "D2" else "--", lw=1, color=colour)
            if ok.any():
                ax.errorbar(x[ok], v[ok], yerr=[(v - lo)[ok], (hi - v)[ok]], fmt="o" if mode == "D2" else "s", ms=4,
                            capsize=2.5, color=colour, label=label)
            if (~ok).any():
                undetermined = True
                ax.plot(x[~ok], v[~ok], "o" if mode == "D2" else "s", ms=5, mfc="white", color=colour,
                        label=f"{label}, not usable")
        ax.set_xlabel(key_label(key))
        ax.set_ylabel(parameter_label(par, q))
        ax.grid(alpha=0.3)
        legend_if_any(ax, fontsize=7)
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    others = [k for k in sweep["keys"] if k != key and len({r[k] for r in rows}) > 1]
    text = f"sweep over {key}: fits of each row's ensemble; bars: 95 % intervals (jackknife over packings, t)"
    if others:
        text += f"\nthe rows also change {', '.join(others)} (sweep/parameters.md)"
    if undetermined:
        text += "\nhollow: fit not usable (no result; the reason in sweep/parameters.md)"
    if left_out:
        text += "\nnot drawn (fewer than two values): " + ", ".join(left_out)
    fig.suptitle(text, fontsize=8)
    fig.tight_layout()
    stem = os.path.join(out, "sweep", "parameters_" + re.sub(r"[^A-Za-z0-9_.-]", "_", key))
    save(fig, stem, out)
    return stem + ".png"


def main(argv=None):
    ap = argparse.ArgumentParser(description="summary of a parameter sweep (fitted parameters against the swept keys)")
    ap.add_argument("out", help="sweep folder (sweep.json, rows/NAME/fit/parameters.csv)")
    ap.add_argument("--no-plots", action="store_true")
    a = ap.parse_args(argv)
    sweep = read_sweep(a.out)
    rows = collect(a.out, sweep)
    header = ["row", *sweep["keys"], "mode", "nu", "quantity", *FIT_COLUMNS]
    d = os.path.join(a.out, "sweep")
    os.makedirs(d, exist_ok=True)
    write_atomic(os.path.join(d, "parameters.md"), markdown(rows, sweep))
    numeric = {c for c in header if c not in ("row", "mode", "quantity", "error_method", "warnings", *sweep["keys"])}
    write_json_atomic(os.path.join(d, "parameters.json"),
                      {"keys": sweep["keys"], "null": "not a finite number (NaN or infinite)",
                       "rows": [{k: (fnum(r, k) if k in numeric else r[k]) for k in header} for r in rows]}, indent=2)
    figures = []
    if not a.no_plots:
        for key in sweep["keys"]:
            if all(number(r["values"][key]) is not None for r in sweep["rows"]):
                figures.append(plot_against(a.out, rows, sweep, key))
            else:
                print(f"demkit.sweep: note: {key} is not numeric in every row: no figure against it (the values "
                      "are in sweep/parameters.md)", file=sys.stderr)
    write_atomic(os.path.join(d, "parameters.csv"), csv_text(rows, header))   # last: the workflow's target
    drawn = [f for f in figures if f]
    print(f"demkit.sweep: {len(sweep['rows'])} rows, {len(rows)} fits -> {d}/parameters.{{csv,md,json}}"
          + (f", {len(drawn)} figure(s)" if drawn else ""), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
