"""Is a calibration's cost smooth at its optimum? Steps coefficients of a stored `dem model` calibration by a tiny
relative amount and reads the cost at each start (Ceres' initial cost, seven digits) without fitting.

    /usr/bin/python3 -m demkit.model_cost_scan ENSEMBLE PARAMETERS.csv --scan n_peak,F_max_b \
        [--rel 1e-7] [--steps 2] [--csv OUT.csv] -- [the calibration's own dem model options]

For each named coefficient and k = -steps..steps the value becomes value x (1 + k rel) in a copy of PARAMETERS.csv,
and `dem model ENSEMBLE --start COPY --max-iterations 1 --no-jackknife --no-plots` (with the options after `--`, those
the calibration was made with) reports the cost there. A smooth cost changes by about rel x its gradient, which is 0
at an optimum, so its seven printed digits stay put; a spread (max - min)/min above 1e-5 is called rough. The
sixteenth round of issue 31 found the isotropic law's cusp this way (docs/model.md, "The isotropic law's cusp": a
relative 1e-7 moved chi2/dof by 1 %). Exit 2 for a coefficient not in the file, 1 when a `dem model` run fails.
"""
import argparse
import csv
import os
import subprocess
import sys
import tempfile

from demkit.atomic import write_atomic

ROUGH = 1e-5   # relative spread above which the cost is called rough (100 x the printed digits' resolution)


def read_rows(path):
    with open(path, newline="") as fh:
        return list(csv.reader(fh))


def initial_cost(stderr):
    """Ceres' initial cost from `dem model`'s report (the cost at the start itself)."""
    key = "Initial cost: "
    if key not in stderr:
        return None
    return float(stderr.split(key, 1)[1].split(",", 1)[0])


def scan_one(dem, ensemble, rows, name, rel, steps, options, work):
    """[(k, value, cost)] for the coefficient `name` stepped by k rel."""
    col = rows[0].index("value")
    i = [r[0] for r in rows].index(name)
    v0 = float(rows[i][col])
    out = []
    for k in range(-steps, steps + 1):
        edited = [list(r) for r in rows]
        edited[i][col] = repr(v0 * (1 + k * rel))
        start = os.path.join(work, "start.csv")
        with open(start, "w", newline="") as fh:
            csv.writer(fh).writerows(edited)
        r = subprocess.run([dem, "model", ensemble, "--start", start, "--max-iterations", "1", "--no-jackknife",
                            "--no-plots", "--out", os.path.join(work, "out"), "--force", *options],
                           capture_output=True, text=True)
        cost = initial_cost(r.stderr)
        if r.returncode not in (0, 1) or cost is None:
            sys.exit(f"model_cost_scan: dem model failed at {name} step {k} (exit {r.returncode}):\n{r.stderr[-2000:]}")
        out.append((k, float(edited[i][col]), cost))
    return out


def summary(name, points):
    costs = [c for _, _, c in points]
    spread = (max(costs) - min(costs)) / min(costs)
    return name, spread, "rough" if spread > ROUGH else "smooth"


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    options = []
    if "--" in argv:
        options = argv[argv.index("--") + 1:]
        argv = argv[:argv.index("--")]
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("ensemble", help="the calibration's ensemble folder (as given to dem model)")
    ap.add_argument("parameters", help="its parameters.csv")
    ap.add_argument("--scan", required=True, help="comma-separated coefficients to step (names of parameters.csv)")
    ap.add_argument("--rel", type=float, default=1e-7, help="relative step (default 1e-7)")
    ap.add_argument("--steps", type=int, default=2, help="steps each side (default 2)")
    ap.add_argument("--dem", default=os.path.join("build", "dem"), help="the dem binary (default build/dem)")
    ap.add_argument("--csv", help="also write every point here (name, k, value, initial_cost [-])")
    a = ap.parse_args(argv)
    rows = read_rows(a.parameters)
    names = [n for n in a.scan.split(",") if n]
    known = [r[0] for r in rows[1:]]
    missing = [n for n in names if n not in known]
    if missing or not names or not (a.rel > 0) or a.steps < 1:
        print(f"model_cost_scan: {', '.join(missing) or 'nothing'} not a coefficient to scan (or --rel <= 0, --steps < 1); "
              f"name coefficients of {a.parameters}: {', '.join(known)}", file=sys.stderr)
        return 2
    lines, table = [], [["name", "k", "value", "initial_cost [-]"]]
    with tempfile.TemporaryDirectory(prefix="model_cost_scan_") as work:
        for name in names:
            points = scan_one(a.dem, a.ensemble, rows, name, a.rel, a.steps, options, work)
            table += [[name, str(k), repr(v), repr(c)] for k, v, c in points]
            n, spread, verdict = summary(name, points)
            lines.append(f"{n}: costs {' '.join(f'{c:.7g}' for _, _, c in points)}; spread {spread:.1e} ({verdict})")
    if a.csv:
        write_atomic(a.csv, "".join(",".join(r) + "\n" for r in table))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
