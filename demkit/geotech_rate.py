"""Rate-dependent element tests (issue 31; docs/geotech.md, "The mu(I) law"): simple shear at
constant normal stress at several shear rates, the mu(I) law of Jop, Forterre & Pouliquen (2006)

    mu(I) = mu_s + (mu_2 - mu_s) / (1 + I_0 / I),

the dilatancy law nu(I) = nu_max - a I (da Cruz et al. 2005), and reruns of any [paths] test at
another rate (the half-rate check of TC_s3).

Two commands:

    /usr/bin/python3 -m demkit.geotech_rate run --out runs/geotech --mu 0.5 --prep loose --level iso_hi \\
        --test SS_cns --rates 1e-5,3e-5,1e-4 [--eps-d 0.6] [--packings 4] [--jobs 2]
        `dem mode --rate-tc R` (--eps-d: ending at that eps_d, not at the scene path's `until`) from the checkpoints of demkit.geotech's preparations (made if absent,
        the same folders: runs/geotech/prep/...), the servo's rate limit 4x the test rate as in the
        scene; curves in OUT/rate/mu_MU/PREP/LEVEL/TEST/rR/mS.csv (skips what exists);
    /usr/bin/python3 -m demkit.geotech_rate analyse runs/geotech/rate --out data/geotech/rate [--store]
        the steady state of every simple-shear curve (mean over the last END_WINDOW of eps_d):
        mu = tau/sigma_n = -sigma_xz/sigma_zz, I = |L_xz| d sqrt(rho/sigma_zz) (d = 2<r>, the
        mean diameter; sigma_zz the held normal stress), nu; the mu(I) and nu(I) fits with
        jackknife intervals over the packings; a table, a figure.

The fit: ordinary least squares of mu(I) through every packing's steady points (all rates), with
log I_0 as the parameter; its 95 % interval is the jackknife over packings (leave one packing
out, refit; SE^2 = (K-1)/K sum (theta_k - theta_mean)^2, Student t with K - 1 degrees of
freedom). A parameter is "not determined" (NaN) where a replicate fails to converge or I_0 runs
to a bound (the data do not reach the plateau it names).
"""
import glob
import math
import os
import re
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy import optimize, stats

from demkit import geotech
from demkit.atomic import write_atomic, write_figure
from demkit.curves import read_curve, read_text, require

END_WINDOW = geotech.END_WINDOW       # eps_d window of the steady state (0.2)
SERVO_FACTOR = 4.0                    # servo.rate_max_tc / test rate, as data/scenes/geotech.toml
LOG_I0_BOUNDS = (math.log(1e-6), math.log(1e2))
STORE_COLUMNS = ("eps_d", "eps_v", "nu", "p_Pa", "sigma_zz_Pa", "sigma_xz_Pa", "rate_xz_1_s", "control_error_rel")


def mu_of_i(i, mu_s, mu_2, i_0):
    """Jop, Forterre & Pouliquen (2006): mu_s + (mu_2 - mu_s) / (1 + I_0 / I)."""
    i = np.asarray(i, float)
    return mu_s + (mu_2 - mu_s) / (1.0 + i_0 / i)


# ------------------------------------------------------------------------------------------
# Steady states of the curves


def diameter_density(comments):
    """(2<r>, rho) from a curve's '# physics:' line: radii uniform in [r_min, r_max]."""
    line = next((c for c in comments if c.startswith("# physics:")), "")
    keys = dict(re.findall(r"([\w.]+)=(\S+)", line))
    try:
        r0, r1 = float(keys["particles.radius_min_m"]), float(keys["particles.radius_max_m"])
        return r0 + r1, float(keys["particles.density_kg_m3"])
    except KeyError as e:
        raise ValueError(f"curve lacks {e.args[0]} in its '# physics:' line (a curve of `dem mode` has it)") from None


def steady_state(path):
    """The steady state of one simple-shear curve: dict of mu, I, nu and their checks."""
    comments, _, _ = read_text(path)
    c = read_curve(path)
    require(c, ("eps_d", "eps_v", "nu", "sigma_zz_Pa", "sigma_xz_Pa", "rate_xz_1_s"), path)
    d, rho = diameter_density(comments)
    x = c["eps_d"]
    end = x >= x[-1] - END_WINDOW
    sn = c["sigma_zz_Pa"][end]
    i_rows = np.abs(c["rate_xz_1_s"][end]) * d * np.sqrt(rho / sn)
    eps_vol = -3.0 * c["eps_v"]
    return {
        "tau_over_sigma_n": float(np.mean(-c["sigma_xz_Pa"][end] / sn)), "inertial": float(np.mean(i_rows)),
        "nu": float(np.mean(c["nu"][end])), "sigma_n_Pa": float(np.mean(sn)),
        "p_over_sigma_n": float(np.mean(c["p_Pa"][end] / sn)) if "p_Pa" in c else math.nan,
        "dilatancy_end": geotech.slope(x[end], -eps_vol[end]), "eps_d_end": float(x[-1]),
        "servo_error_mean": float(np.mean(c["control_error_rel"][x >= geotech.TRANSIENT_EPS]))
        if "control_error_rel" in c else math.nan,
    }


def collect(root):
    """{(mu, prep, level, test, rate): {packing: path}} of a rate run folder."""
    groups = {}
    for path in sorted(glob.glob(os.path.join(root, "mu_*", "*", "*", "*", "r*", "m*.csv"))):
        parts = path.split(os.sep)
        key = (parts[-6][3:], parts[-5], parts[-4], parts[-3], parts[-2][1:])
        groups.setdefault(key, {})[parts[-1][:-4]] = path
    return groups


# ------------------------------------------------------------------------------------------
# The fits


def fit_mu_i(i, mu):
    """Least-squares (mu_s, mu_2, I_0) of mu(I) through the points; NaNs where it fails or I_0
    sits at a bound of LOG_I0_BOUNDS."""
    i, mu = np.asarray(i, float), np.asarray(mu, float)
    if i.size < 4:
        return (math.nan,) * 3
    f = lambda p: mu_of_i(i, p[0], p[1], math.exp(p[2])) - mu
    best = None
    for log_i0 in np.log([1e-3, 1e-2, 1e-1, 1.0]):       # starts across the range: the fit is not convex
        p0 = [float(np.min(mu)), float(np.max(mu)) + 0.05, log_i0]
        try:
            r = optimize.least_squares(f, p0, bounds=([-np.inf, -np.inf, LOG_I0_BOUNDS[0]],
                                                      [np.inf, np.inf, LOG_I0_BOUNDS[1]]))
        except ValueError:
            continue
        if r.success and (best is None or r.cost < best.cost):
            best = r
    if best is None or min(abs(best.x[2] - b) for b in LOG_I0_BOUNDS) < 1e-3:
        return (math.nan,) * 3
    return float(best.x[0]), float(best.x[1]), float(math.exp(best.x[2]))


def fit_line(i, y):
    """Least-squares (intercept, slope) of y = y_0 + b I; NaNs with fewer than 3 points."""
    if len(i) < 3:
        return math.nan, math.nan
    slope, icpt = np.polyfit(np.asarray(i, float), np.asarray(y, float), 1)
    return float(icpt), float(slope)


def fit_nu_i(i, nu):
    """Least-squares (nu_max, a) of nu = nu_max - a I (da Cruz et al. 2005)."""
    nu_max, slope = fit_line(i, nu)
    return nu_max, -slope


def jackknife(points, fit):
    """points: {packing: (x array, y array)}; fit(x, y) -> tuple. Returns (estimates on all
    packings, 95 % half-widths from the jackknife over packings; NaN where not determined)."""
    keys = sorted(points)
    cat = lambda ks: (np.concatenate([points[k][0] for k in ks]), np.concatenate([points[k][1] for k in ks]))
    full = np.array(fit(*cat(keys)), float)
    if len(keys) < 3:
        return full, np.full(full.shape, math.nan)
    reps = np.array([fit(*cat([k for k in keys if k != out])) for out in keys], float)
    n = len(keys)
    se = np.sqrt((n - 1) / n * np.sum((reps - reps.mean(axis=0)) ** 2, axis=0))
    half = stats.t.ppf(0.975, n - 1) * se
    half[~np.isfinite(full) | np.any(~np.isfinite(reps), axis=0)] = math.nan
    return full, half


def chi2_dof(i_mean, mu_mean, mu_half, k, params):
    """chi^2/dof of the per-rate means about the fitted law, each weighted by its spread over the
    packings (a consistency check of the law's form; the parameters' intervals are the jackknife's)."""
    se = np.asarray(mu_half, float) / stats.t.ppf(0.975, max(k - 1, 1))
    ok = np.isfinite(se) & (se > 0)
    if ok.sum() <= 3 or not np.all(np.isfinite(params)):
        return math.nan
    return float(np.sum(((mu_of_i(i_mean[ok], *params) - mu_mean[ok]) / se[ok]) ** 2) / (ok.sum() - 3))


# ------------------------------------------------------------------------------------------
# Analysis

STEADY_KEYS = ("inertial", "tau_over_sigma_n", "nu", "sigma_n_Pa", "p_over_sigma_n", "dilatancy_end", "eps_d_end", "servo_error_mean")


def rate_table(groups):
    """Per (mu, prep, level, test, rate): the steady states per packing and their means with
    95 % intervals. Returns (member rows, mean rows)."""
    members, means = [], []
    shear = [k for k in groups if k[3] == "SS_cns"]
    for key in sorted(shear, key=lambda k: (k[:4], float(k[4]))):
        states = {pk: steady_state(path) for pk, path in sorted(groups[key].items())}
        for pk, s in states.items():
            members.append({**dict(zip(("mu", "prep", "level", "test", "rate_tc"), key)), "packing": pk, **s})
        row = dict(zip(("mu", "prep", "level", "test", "rate_tc"), key))
        for name in STEADY_KEYS:
            m, h, k = geotech.mean_ci([s[name] for s in states.values()])
            row[name], row[name + "_ci95"], row["K"] = m, h, k
        row["volume_stationary"] = geotech.stationary(row["dilatancy_end"], row["dilatancy_end_ci95"],
                                                      geotech.CS_DILATANCY_TOL)
        means.append(row)
    return members, means


def unsteady(means):
    """The (mu, prep, level, test, rate) whose volume is still changing at the end (stationary
    'no': the interval of d eps_vol/d eps_d wholly outside the tolerance): no steady state, left
    out of the fits."""
    return {tuple(r[k] for k in ("mu", "prep", "level", "test", "rate_tc")) for r in means
            if r["volume_stationary"] == "no"}


def law_fits(members, skip=frozenset()):
    """Per (mu, prep, level) of the simple-shear rows not in skip: mu(I) and nu(I) with jackknife
    intervals."""
    out = []
    key = lambda r: tuple(r[k] for k in ("mu", "prep", "level", "test", "rate_tc"))
    cells = sorted({(r["mu"], r["prep"], r["level"]) for r in members if r["test"] == "SS_cns"})
    for cell in cells:
        rows = [r for r in members if (r["mu"], r["prep"], r["level"]) == cell and r["test"] == "SS_cns"
                and key(r) not in skip]
        pts = lambda y: {pk: (np.array([r["inertial"] for r in rows if r["packing"] == pk]),
                              np.array([r[y] for r in rows if r["packing"] == pk]))
                         for pk in {r["packing"] for r in rows}}
        n_rates = len({r["rate_tc"] for r in rows})
        nan = lambda n: (np.full(n, math.nan), np.full(n, math.nan))
        # three parameters need four rates; a line three
        (mu_s, mu_2, i_0), h_mu = jackknife(pts("tau_over_sigma_n"), fit_mu_i) if n_rates >= 4 else nan(3)
        (nu_max, a), h_nu = jackknife(pts("nu"), fit_nu_i) if n_rates >= 3 else nan(2)
        (mu_0, b), h_lin = jackknife(pts("tau_over_sigma_n"), fit_line) if n_rates >= 3 else nan(2)
        i_all = [r["inertial"] for r in rows]
        out.append({"mu": cell[0], "prep": cell[1], "level": cell[2], "K": len(pts("nu")),
                    "rates": n_rates, "I_min": min(i_all), "I_max": max(i_all),
                    "mu_s": mu_s, "mu_s_ci95": h_mu[0], "mu_2": mu_2, "mu_2_ci95": h_mu[1],
                    "I_0": i_0, "I_0_ci95": h_mu[2], "nu_max": nu_max, "nu_max_ci95": h_nu[0],
                    "a": a, "a_ci95": h_nu[1], "mu_0_lin": mu_0, "mu_0_lin_ci95": h_lin[0],
                    "b_lin": b, "b_lin_ci95": h_lin[1]})
    return out


def add_chi2(fits, means):
    for f in fits:
        rows = [r for r in means if (r["mu"], r["prep"], r["level"], r["test"]) == (f["mu"], f["prep"], f["level"], "SS_cns")
                and r["volume_stationary"] != "no"]
        f["chi2_dof"] = chi2_dof(np.array([r["inertial"] for r in rows]), np.array([r["tau_over_sigma_n"] for r in rows]),
                                 np.array([r["tau_over_sigma_n_ci95"] for r in rows]), f["K"], (f["mu_s"], f["mu_2"], f["I_0"]))
    return fits


def rate_pairs(groups):
    """Tests other than simple shear run at two or more rates (the half-rate check): per packing
    the difference of phi_cs, phi_peak and nu_cs between each rate and the fastest, with the
    95 % interval of the paired differences over the packings."""
    out = []
    tests = sorted({k[:4] for k in groups if k[3] != "SS_cns"})
    for t in tests:
        rates = sorted((k[4] for k in groups if k[:4] == t), key=float)
        ref = {pk: geotech.curve_values(read_curve(p)) for pk, p in groups[t + (rates[-1],)].items()}
        for r in rates[:-1]:
            cur = {pk: geotech.curve_values(read_curve(p)) for pk, p in groups[t + (r,)].items()}
            row = dict(zip(("mu", "prep", "level", "test"), t), rate_tc=r, rate_ref_tc=rates[-1])
            for q in ("phi_cs_deg", "phi_peak_deg", "nu_cs", "inertial_max"):
                row[q], _, _ = geotech.mean_ci([v[q] for v in cur.values()])
                row[q + "_ref"], _, _ = geotech.mean_ci([v[q] for v in ref.values()])
                d, h, k = geotech.mean_ci([cur[pk][q] - ref[pk][q] for pk in cur if pk in ref])
                row["d_" + q], row["d_" + q + "_ci95"], row["K"] = d, h, k
            out.append(row)
    return out


def write_rows(path, rows):
    if not rows:
        return
    header = list(rows[0])
    fmt = lambda v: geotech.fmt(v) if isinstance(v, float) else str(v)
    text = ",".join(header) + "\n" + "".join(",".join(fmt(r[h]) for h in header) + "\n" for r in rows)
    write_atomic(path, text)


def pm(v, h, digits=3):
    """'v ± h', 'v (not determined)' without an interval."""
    if not math.isfinite(v):
        return "not determined"
    return f"{v:.{digits}g} ± {h:.2g}" if math.isfinite(h) else f"{v:.{digits}g} (interval not determined)"


def write_report(fits, means, pairs, out):
    lines = ["# Rate-dependent tests (demkit.geotech_rate analyse; docs/geotech.md)", "",
             "## Steady states of simple shear at constant normal stress (mean ± 95 % over packings)", "",
             "| mu | prep | p level | rate·t_c | K | I | τ/σ_n | ν | dε_vol/dε_d | volume stationary (fitted if not 'no') | servo error mean |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in (r for r in means if r["test"] == "SS_cns"):
        lines.append(f"| {r['mu']} | {r['prep']} | {r['level']} | {r['rate_tc']} | {r['K']} | "
                     f"{pm(r['inertial'], r['inertial_ci95'])} | {pm(r['tau_over_sigma_n'], r['tau_over_sigma_n_ci95'])} | "
                     f"{pm(r['nu'], r['nu_ci95'])} | {pm(r['dilatancy_end'], r['dilatancy_end_ci95'], 2)} | "
                     f"{r['volume_stationary']} | {100 * r['servo_error_mean']:.1f} % |")
    lines += ["", "## mu(I) = mu_s + (mu_2 - mu_s)/(1 + I_0/I), the line mu_0 + b I, and nu = nu_max - a I (jackknife over packings)", "",
              "| mu | prep | p level | K | rates | I range | μ_s | μ_2 | I_0 | χ²/dof | μ_0 + b I: μ_0 | b | ν_max | a |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for f in fits:
        lines.append(f"| {f['mu']} | {f['prep']} | {f['level']} | {f['K']} | {f['rates']} | "
                     f"{f['I_min']:.2g}–{f['I_max']:.2g} | {pm(f['mu_s'], f['mu_s_ci95'])} | "
                     f"{pm(f['mu_2'], f['mu_2_ci95'])} | {pm(f['I_0'], f['I_0_ci95'], 2)} | {f['chi2_dof']:.2g} | "
                     f"{pm(f['mu_0_lin'], f['mu_0_lin_ci95'])} | {pm(f['b_lin'], f['b_lin_ci95'], 2)} | "
                     f"{pm(f['nu_max'], f['nu_max_ci95'], 4)} | {pm(f['a'], f['a_ci95'], 3)} |")
    if pairs:
        lines += ["", "## Rate checks (slower minus faster, paired per packing, mean ± 95 %)", "",
                  "| mu | prep | p level | test | rate·t_c / reference | K | φ_cs (deg) | Δφ_cs | Δφ_peak | Δν_cs | I_max |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in pairs:
            lines.append(f"| {r['mu']} | {r['prep']} | {r['level']} | {r['test']} | {r['rate_tc']} / {r['rate_ref_tc']} | "
                         f"{r['K']} | {r['phi_cs_deg']:.2f} / {r['phi_cs_deg_ref']:.2f} | "
                         f"{pm(r['d_phi_cs_deg'], r['d_phi_cs_deg_ci95'], 2)} | {pm(r['d_phi_peak_deg'], r['d_phi_peak_deg_ci95'], 2)} | "
                         f"{pm(r['d_nu_cs'], r['d_nu_cs_ci95'], 2)} | {r['inertial_max']:.2g} / {r['inertial_max_ref']:.2g} |")
    write_atomic(os.path.join(out, "report.md"), "\n".join(lines) + "\n")


def plot(fits, members, out, skip=frozenset()):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    for k, f in enumerate(fits):
        rows = [r for r in members if (r["mu"], r["prep"], r["level"], r["test"]) == (f["mu"], f["prep"], f["level"], "SS_cns")]
        col, lab = f"C{k}", f"μ = {f['mu']}, {f['prep']}, {f['level']}"
        i, m, n = (np.array([r[q] for r in rows]) for q in ("inertial", "tau_over_sigma_n", "nu"))
        left = np.array([tuple(r[k] for k in ("mu", "prep", "level", "test", "rate_tc")) in skip for r in rows], bool)
        for a, y in ((ax, m), (bx, n)):
            a.plot(i[~left], y[~left], "o", ms=3, color=col, label=lab)
            a.plot(i[left], y[left], "o", ms=4, mfc="none", color=col)   # not steady: not fitted
        g = np.geomspace(i[~left].min(), i[~left].max(), 100)       # over the fitted range
        if math.isfinite(f["I_0"]):
            ax.plot(g, mu_of_i(g, f["mu_s"], f["mu_2"], f["I_0"]), "-", color=col, lw=1)
        elif math.isfinite(f["b_lin"]):                              # Jop's law not determined: the line
            ax.plot(g, f["mu_0_lin"] + f["b_lin"] * g, "--", color=col, lw=1)
        bx.plot(g, f["nu_max"] - f["a"] * g, "-", color=col, lw=1)
    for a, y in ((ax, "τ/σ_n (steady)"), (bx, "ν (steady)")):
        a.set_xscale("log")
        a.set_xlabel("inertial number I = γ̇ d √(ρ/σ_n)")
        a.set_ylabel(y)
    ax.legend(fontsize=7)
    ax.set_title("points: packings (open: volume not steady, not fitted)\nsolid: Jop et al.'s μ(I); dashed: μ_0 + b I where it is not determined", fontsize=8)
    bx.set_title("lines: ν = ν_max − a I fitted", fontsize=8)
    fig.tight_layout()
    write_figure(fig, os.path.join(out, "mu_i"), exts=("png",), dpi=110)


def store(groups, out):
    """Trimmed copies of the curves (simple shear: STORE_COLUMNS; other tests: demkit.geotech's
    TRIM): `analyse OUT/curves` gives the same tables."""
    for key, paths in groups.items():
        mu, prep, level, test, rate = key
        for pk, src in paths.items():
            dst = os.path.join(out, "curves", f"mu_{mu}", prep, level, test, f"r{rate}", pk + ".csv")
            os.makedirs(os.path.dirname(dst), exist_ok=True)
            if test != "SS_cns":
                geotech.trim_curve(src, dst)
                continue
            comments, header, rows = read_text(src)
            keep = [header.index(c) for c in STORE_COLUMNS if c in header]
            text = "\n".join(comments) + "\n" + ",".join(header[k] for k in keep) + "\n"
            text += "".join(",".join(r[k] for k in keep) + "\n" for r in rows)
            write_atomic(dst, text)


def analyse(root, out, plots=True):
    groups = collect(root)
    if not groups:
        raise SystemExit(f"no curves under {root}/mu_*/PREP/LEVEL/TEST/rRATE/mS.csv: run `run` first")
    os.makedirs(out, exist_ok=True)
    members, means = rate_table(groups)
    fits = add_chi2(law_fits(members, unsteady(means)), means)
    pairs = rate_pairs(groups)
    write_rows(os.path.join(out, "steady_members.csv"), members)
    write_rows(os.path.join(out, "steady_states.csv"), means)
    write_rows(os.path.join(out, "mu_i_fit.csv"), fits)
    write_rows(os.path.join(out, "rate_checks.csv"), pairs)
    write_report(fits, means, pairs, out)
    if plots and fits:
        plot(fits, members, out, unsteady(means))
    return fits, means, pairs


# ------------------------------------------------------------------------------------------
# Running


def stop_override(scene, test, eps_d):
    """`--set paths.TEST=...`: the scene's path with its last stage ending at eps_d instead of its own
    `until` (the mu(I) series keeps the length it was made with when the scene's test grows)."""
    stages = geotech.load_scene(scene)["paths"][test]
    stages[-1] = {**stages[-1], "until": {"eps_d": float(eps_d)}}
    return ["--set", f"paths.{test}={geotech.toml_inline(stages)}"]


def run_one(dem, scene, root, prep, mu, seed, level, test, rate, eps_d=None):
    out = os.path.join(root, "rate", f"mu_{mu}", prep, level, test, f"r{rate}", f"m{seed}.csv")
    if os.path.exists(out):
        return 0
    ckpt = glob.glob(os.path.join(geotech.prep_dir(root, prep, mu, seed, level), "checkpoints", f"{level}_phi*.ckpt"))
    if len(ckpt) != 1:
        return -1
    os.makedirs(os.path.dirname(out), exist_ok=True)
    servo = SERVO_FACTOR * float(rate)
    stop = stop_override(scene, test, eps_d) if eps_d is not None else []
    return geotech.run_cmd([dem, "mode", "--scene", scene, "--packing", ckpt[0], "--mode", test, "--out", out,
                            "--rate-tc", rate, "--set", f"servo.rate_max_tc={servo:.6g}", *stop,
                            "--set", f"contact.friction={mu}", "--threads", "1", "--quiet"], out[:-4] + ".log")


def run(args):
    seeds = range(args.first_seed, args.first_seed + args.packings)
    rates = args.rates.split(",")
    for r in rates:
        if not (float(r) > 0):
            raise SystemExit(f"--rates: {r} is not a positive number (rates times t_c, e.g. 1e-5,3e-5)")
    with ThreadPoolExecutor(args.jobs) as pool:
        preps = [(args.prep, args.mu, s, args.level == geotech.LOW_LEVEL) for s in seeds]
        for (p, mu, s, _), rc in zip(preps, pool.map(lambda a: geotech.prepare(args.dem, args.scene, args.out, *a), preps)):
            if rc:
                print(f"preparation {p} mu={mu} m{s} failed ({rc})", file=sys.stderr)
        # slowest first: the longest runs start while the pool is full
        jobs = [(args.prep, args.mu, s, args.level, args.test, r) for r in sorted(rates, key=float) for s in seeds]
        for job, rc in zip(jobs, pool.map(lambda a: run_one(args.dem, args.scene, args.out, *a, eps_d=args.eps_d), jobs)):
            print(f"{' '.join(map(str, job))}: {'ok' if rc == 0 else f'failed ({rc})'}", flush=True)


def main(argv=None):
    ap, r = geotech.cli("demkit.geotech_rate", __doc__.split("\n\n")[0], "run one test of the scene at several rates",
                        "steady states, the mu(I) and nu(I) fits, rate checks", packings=4,
                        out_help="the demkit.geotech run folder (its prep/ is reused)",
                        root_help="OUT/rate of `run`, or a stored copy's curves/ folder")
    r.add_argument("--mu", default="0.5")
    r.add_argument("--prep", default="loose", choices=sorted(geotech.PREPS))
    r.add_argument("--level", default="iso_hi", choices=(*geotech.LEVELS, geotech.LOW_LEVEL))
    r.add_argument("--test", default="SS_cns")
    r.add_argument("--rates", required=True, help="comma-separated rates times t_c, e.g. 1e-5,3e-5,1e-4")
    r.add_argument("--eps-d", type=float, default=None,
                   help="end the test at this eps_d instead of its scene path's `until` (the stored mu(I) series: 0.6)")
    geotech.dispatch(ap.parse_args(argv), run, analyse, lambda root, out: store(collect(root), out))


if __name__ == "__main__":
    main()
