"""Powder flowability from the shear-tester procedure (Jenike; Schulze's ring shear tester,
ASTM D6773) run as a loading path (data/scenes/shear_tester.toml, docs/powders.md).

The construction (Schulze, "Powders and Bulk Solids", Springer 2008, ch. 3; Jenike 1964):
- the yield locus (YL): the straight line tau = c + sigma tan(phi_lin) fitted (least squares)
  through the shear-to-failure points (sigma_n, tau_f), tau_f the peak shear stress of the
  shear stage at sigma_n after pre-shear at sigma_pre; c is the cohesion (its intercept);
- the unconfined yield strength sigma_c: the Mohr circle through the origin (sigma_3 = 0)
  tangent to the YL, sigma_c = 2 c cos(phi_lin) / (1 - sin(phi_lin));
- the major consolidation stress sigma_1: the Mohr circle through the pre-shear point
  (sigma_pre, tau_pre) tangent to the YL (of the two such circles the one that touches the YL at
  or left of the pre-shear point, where the YL ends; a pre-shear point above the YL, where there is
  none: the circle through it whose tangent there has the YL's slope, Jenike's end point E),
  sigma_1 = its centre + radius;
- the effective angle of internal friction phi_e: the line through the origin tangent to that
  circle, sin(phi_e) = (sigma_1 - sigma_2) / (sigma_1 + sigma_2);
- ffc = sigma_1 / sigma_c and its class (Jenike; Schulze's table): ffc < 1 not flowing, 1-2 very
  cohesive, 2-4 cohesive, 4-10 easy-flowing, > 10 free-flowing. A locus without cohesion
  (c <= 0) has sigma_c = 0 and ffc = infinity (free-flowing).

Errors over packings: every quantity is computed per packing (each sample its own locus) and then
averaged; intervals are Student's t (K - 1 degrees of freedom) 95 %. ffc is averaged through its
inverse sigma_c / sigma_1 (finite through a zero cohesion), and its interval is the inverse of
that interval (the upper end infinite when the interval of 1/ffc reaches 0).

    /usr/bin/python3 -m demkit.powders --out DIR --label NAME RUN [RUN ...]      # one adhesion level
    /usr/bin/python3 -m demkit.powders --table --out DIR LEVEL_DIR [LEVEL_DIR ...]  # the table over levels
    /usr/bin/python3 -m demkit.powders --sweep --out DIR SWEEP_DIR    # a `dem ensemble --sweep` of the scene
"""
import argparse
import csv
import glob
import io
import json
import math
import os
import sys

import numpy as np
from scipy import stats

from demkit.atomic import write_atomic, write_figure, write_json_atomic
from demkit.curves import CurveError, read_curve, require

CLASSES = ((1.0, "not flowing"), (2.0, "very cohesive"), (4.0, "cohesive"), (10.0, "easy-flowing"),
           (math.inf, "free-flowing"))
PRESHEAR_TAIL = 0.5     # the steady pre-shear value: mean over the last half of a pre-shear stage's rows
PEAK_WINDOW = 5         # rows (0.01 of strain at the scene's sampling) of the running mean whose peak is tau_f


def flow_class(ffc):
    """The flowability class of ffc = sigma_1 / sigma_c (Jenike's boundaries 1, 2, 4, 10)."""
    if not (ffc >= 0):
        raise ValueError(f"ffc = {ffc} is not a non-negative number")
    for bound, name in CLASSES:
        if ffc < bound:
            return name
    return CLASSES[-1][1]


def fit_yield_locus(sigma_n, tau_f):
    """(c, phi_lin [rad]) of the least-squares line tau = c + sigma tan(phi_lin) through the
    shear-to-failure points (at least two)."""
    sigma_n, tau_f = np.asarray(sigma_n, float), np.asarray(tau_f, float)
    if sigma_n.size < 2 or np.ptp(sigma_n) <= 0:
        raise ValueError("a yield locus needs shear-to-failure points at two or more normal stresses")
    slope, c = np.polyfit(sigma_n, tau_f, 1)
    return float(c), float(math.atan(slope))


def unconfined_yield_strength(c, phi):
    """sigma_c: the Mohr circle through the origin tangent to tau = c + sigma tan(phi); 0 when c <= 0."""
    return 2 * c * math.cos(phi) / (1 - math.sin(phi)) if c > 0 else 0.0


def steady_state_circle(c, phi, sigma_pre, tau_pre):
    """(centre, radius) of the Mohr circle through the pre-shear point tangent to the YL.
    Tangency: radius = c cos(phi) + centre sin(phi); through the point: (sigma_pre - centre)^2 +
    tau_pre^2 = radius^2, a quadratic in the centre; of its two roots the circle whose tangent point
    lies at or left of the pre-shear point is taken (the YL ends at the pre-shear point). A pre-shear point
    above the YL (no such circle; a locus that is concave at small stresses) gives the circle through
    the point whose tangent there has the YL's slope (Jenike's end point E of the locus:
    centre sigma_pre + tau_pre tan(phi), radius tau_pre / cos(phi))."""
    sp, cp = math.sin(phi), math.cos(phi)
    a = cp * cp
    b = -2 * (sigma_pre + c * sp * cp)
    k = sigma_pre ** 2 + tau_pre ** 2 - (c * cp) ** 2
    disc = b * b - 4 * a * k
    if disc < 0:     # the point lies above the locus: the circle through it with the YL's slope there
        return sigma_pre + tau_pre * math.tan(phi), tau_pre / cp
    else:   # the root whose tangent point (centre - radius sin(phi)) lies at or left of the point
        roots = sorted(((-b - math.sqrt(disc)) / (2 * a), (-b + math.sqrt(disc)) / (2 * a)))
        left = [r for r in roots if r - (c * cp + r * sp) * sp <= sigma_pre * (1 + 1e-12)]
        centre = left[-1] if left else roots[0]
    return centre, c * cp + centre * sp


def analyse_locus(points, preshear):
    """The powder engineer's numbers from shear-to-failure points [(sigma_n, tau_f), ...] and the
    pre-shear point (sigma_pre, tau_pre), stresses in Pa: a dict with c, phi_lin_deg, sigma_c,
    sigma_1, sigma_2, phi_e_deg, ffc (inf without cohesion), inv_ffc = sigma_c / sigma_1, class."""
    sn, tf = zip(*points)
    c, phi = fit_yield_locus(sn, tf)
    sigma_c = unconfined_yield_strength(c, phi)
    centre, radius = steady_state_circle(c, phi, *preshear)
    s1, s2 = centre + radius, centre - radius
    inv = sigma_c / s1
    ffc = 1 / inv if inv > 0 else math.inf
    return {"c_Pa": c, "phi_lin_deg": math.degrees(phi), "sigma_c_Pa": sigma_c, "sigma_1_Pa": s1,
            "sigma_2_Pa": s2, "phi_e_deg": math.degrees(math.asin(radius / centre)), "ffc": ffc,
            "inv_ffc": inv, "class": flow_class(ffc), "sigma_pre_Pa": preshear[0], "tau_pre_Pa": preshear[1],
            "points": [list(p) for p in points]}


# ------------------------------------------------------------------------------------------
# Reading a run


def shear_test_points(curve, path="curve"):
    """From a shear-tester path curve: the shear-to-failure points (sigma_n, tau_f) of its stages
    named shear_*, tau_f = the peak of tau = -sigma_xz (a running mean over PEAK_WINDOW rows) and
    sigma_n = sigma_zz (the same mean) there, and the
    pre-shear point: the mean (sigma_zz, tau) over the last half of each preshear* stage's rows,
    averaged over those stages. Also the servo's error on sigma_zz, the mean overlap and the
    coordination number at the end of the pre-shear (for the Bond number and Rumpf)."""
    require(curve, ["stage", "sigma_zz_Pa", "sigma_xz_Pa", "overlap_mean_rel", "C", "nu"], path)
    stage = curve["stage"]
    names = list(dict.fromkeys(stage.tolist()))
    tau = -curve["sigma_xz_Pa"]
    points, pre, err, tails = [], [], [], []
    for name in names:
        rows = np.flatnonzero(stage == name)
        if name.startswith("shear_") and rows.size:
            # the peak of tau smoothed over PEAK_WINDOW rows: the max of the raw, noisy signal is biased up
            w = min(PEAK_WINDOW, rows.size)
            kern = np.ones(w) / w
            t_s = np.convolve(tau[rows], kern, mode="valid")
            s_s = np.convolve(curve["sigma_zz_Pa"][rows], kern, mode="valid")
            k = int(np.argmax(t_s))
            points.append((float(s_s[k]), float(t_s[k])))
        if name.startswith("preshear") and rows.size >= 4:
            tail = rows[int(rows.size * (1 - PRESHEAR_TAIL)):]
            tails.append(tail)
            pre.append((curve["sigma_zz_Pa"][tail].mean(), tau[tail].mean()))
            if "target_zz_Pa" in curve:
                t = curve["target_zz_Pa"][tail]
                err.extend(np.abs(curve["sigma_zz_Pa"][tail] / t - 1))
    if len(points) < 2 or not pre:
        raise CurveError(f"{path}: needs stages preshear* and two or more shear_* (has {', '.join(names)})")
    tail = np.concatenate(tails)
    extra = {"overlap_mean_rel": float(curve["overlap_mean_rel"][tail].mean()), "C": float(curve["C"][tail].mean()),
             **inertial_numbers(curve, tail),
             "nu": float(curve["nu"][tail].mean()),
             "servo_error_mean": float(np.mean(err)) if err else math.nan,
             "servo_error_max": float(np.max(err)) if err else math.nan}
    return points, tuple(np.mean(pre, axis=0)), extra


def inertial_numbers(curve, preshear_rows):
    """The inertial number I (curve column inertial_number) averaged over the steady pre-shear rows
    and over the shear-to-failure stages (NaN where the curve has no such column)."""
    if "inertial_number" not in curve:
        return {"I_preshear": math.nan, "I_shear": math.nan}
    inertial = curve["inertial_number"]
    shear = np.array([s.startswith("shear_") for s in curve["stage"]])
    return {"I_preshear": float(inertial[preshear_rows].mean()),
            "I_shear": float(inertial[shear].mean()) if shear.any() else math.nan}


def find_curve(run):
    """The shear-tester curve of a run folder (deviatoric/shear_tester_phi*.csv) or a CSV path."""
    if os.path.isfile(run):
        return run
    hits = sorted(glob.glob(os.path.join(run, "deviatoric", "shear_tester_phi*.csv")))
    if not hits:
        raise CurveError(f"{run}: no deviatoric/shear_tester_phi*.csv (run data/scenes/shear_tester.toml there)")
    return hits[0]


def run_cost(run):
    """(time steps, wall seconds) of a run folder, summed over its manifest's stages (NaN if none)."""
    try:
        with open(os.path.join(run, "manifest.json")) as fh:
            outs = json.load(fh).get("outputs", [])
    except (OSError, ValueError):
        return math.nan, math.nan
    timed = [o for o in outs if "steps" in o]
    if not timed:
        return math.nan, math.nan
    return float(sum(o["steps"] for o in timed)), float(sum(o["wall_s"] for o in timed))


def cpu_seconds(run):
    """User + system CPU seconds of a run from RUN/cpu_time.txt ("USER SYS", as `/usr/bin/time -f
    "%U %S" -o RUN/cpu_time.txt` writes it around `dem run`; the runs' loop in data/powders/README.md);
    NaN where there is none."""
    try:
        with open(os.path.join(run, "cpu_time.txt")) as fh:
            user, sys_ = fh.read().split()[-2:]
        return float(user) + float(sys_)
    except (OSError, ValueError):
        return math.nan


def analyse_run(run):
    path = find_curve(run)
    points, pre, extra = shear_test_points(read_curve(path), path)
    out = analyse_locus(points, pre)
    out.update(extra)
    out["run"] = run
    out["steps"], out["wall_s"] = run_cost(run) if os.path.isdir(run) else (math.nan, math.nan)
    out["dt_over_tc"] = scene_value(run, "integration", "dt_over_tc", 0.02) if os.path.isdir(run) else math.nan
    out["cpu_s"] = cpu_seconds(run)
    return out


def scene_value(run, section, key, default):
    """A number of a run folder's scene.toml (default where the key is absent)."""
    import tomllib
    with open(os.path.join(run, "scene.toml"), "rb") as fh:
        return float(tomllib.load(fh).get(section, {}).get(key, default))


# ------------------------------------------------------------------------------------------
# Over packings


def mean_ci(values):
    """(mean, half-width of the 95 % Student-t interval, SD, K) of finite values."""
    v = np.asarray([x for x in values if math.isfinite(x)], float)
    if v.size == 0:
        return math.nan, math.nan, math.nan, 0
    if v.size == 1:
        return float(v[0]), math.nan, math.nan, 1
    sd = float(v.std(ddof=1))
    return float(v.mean()), float(stats.t.ppf(0.975, v.size - 1) * sd / math.sqrt(v.size)), sd, int(v.size)


QUANTITIES = ("sigma_pre_Pa", "tau_pre_Pa", "sigma_1_Pa", "sigma_c_Pa", "c_Pa", "phi_lin_deg", "phi_e_deg",
              "nu", "C", "overlap_mean_rel", "servo_error_mean", "servo_error_max", "steps", "wall_s", "I_preshear",
              "I_shear", "dt_over_tc", "cpu_s")


def summarise(members, label="", extra=None):
    """Mean and 95 % interval of every quantity over the packings; ffc through 1/ffc."""
    s = {"label": label, "K": len(members)}
    for q in QUANTITIES + ("inv_ffc",):
        m, h, sd, _ = mean_ci([r.get(q, math.nan) for r in members])
        s[q], s[q + "_ci95"], s[q + "_sd"] = m, h, sd
    inv, h = s["inv_ffc"], s["inv_ffc_ci95"]
    s["ffc"] = 1 / inv if inv > 0 else math.inf
    s["ffc_lo"] = 1 / (inv + h) if math.isfinite(h) and inv + h > 0 else math.nan
    s["ffc_hi"] = 1 / (inv - h) if math.isfinite(h) and inv - h > 0 else math.inf
    s["class"] = flow_class(s["ffc"])
    s["class_lo"] = flow_class(s["ffc_lo"]) if math.isfinite(s["ffc_lo"]) else ""
    s["class_hi"] = flow_class(s["ffc_hi"])
    s.update(extra or {})
    return s


# ------------------------------------------------------------------------------------------
# The adhesion: pull-off force of Luding's law, Bond number, Rumpf's tensile strength


def luding_pull_off(k1, kp, kc, phi_f, a12, delta_max):
    """The largest tensile force [N] a Luding contact loaded to delta_max can hold: unloading along
    k2 (delta - delta0) meets the adhesive limit -kc delta at delta_c = k2 delta0 / (k2 + kc), so
    f_pull = kc k2 delta0 / (k2 + kc) = kc (k2 - k1) delta_max / (k2 + kc), k2 = k1 + (kp - k1)
    delta_max / delta* (kp beyond delta*, delta0 then phi_f 2 a12); 0 without adhesion."""
    d0_lim = phi_f * 2 * a12
    d_star = kp / (kp - k1) * d0_lim
    if delta_max >= d_star:
        return kc * kp * d0_lim / (kp + kc)
    k2 = k1 + (kp - k1) * delta_max / d_star
    return kc * (k2 - k1) * delta_max / (k2 + kc)


def bond_number(f_pull, sigma, d):
    """Bo = f_pull / (sigma d^2): the pull-off force of a typical contact over the typical
    confining force at the stress sigma [Pa] on a particle of diameter d [m]."""
    return f_pull / (sigma * d * d)


def rumpf_tensile_strength(nu, coordination, f_bond, d):
    """Rumpf (1958): sigma_t = nu C F / (pi d^2) [Pa] for equal spheres of diameter d, volume
    fraction nu, C bonds per particle of strength F, isotropically distributed, all failing at
    once across the fracture plane (the (1 - eps)/eps F/d^2 form follows with C eps ~ pi)."""
    return nu * coordination * f_bond / (math.pi * d * d)


# ------------------------------------------------------------------------------------------
# Compaction and tensile strength (data/scenes/powder_compaction.toml)

def stage_ends(curve, prefix):
    """[(stage, sigma_zz [Pa], nu, control error, E_kin/E_pot)] at the last row of each stage whose
    name starts with prefix, in order (the packing at rest at that stage's target)."""
    out = []
    for name in dict.fromkeys(curve["stage"].tolist()):
        if name.startswith(prefix):
            i = np.flatnonzero(curve["stage"] == name)[-1]
            out.append((name, float(curve["sigma_zz_Pa"][i]), float(curve["nu"][i]),
                        float(curve["control_error_rel"][i]), float(curve["E_kin_J"][i] / curve["E_pot_J"][i])))
    return out


def compaction_tensile(run):
    """From a run of powder_compaction.toml: the loose state (the stress-controlled preparation's
    end), nu at rest at each load and unload step (sigma_zz, nu), the uniaxial tensile strength
    -min(sigma_zz) of the compaction path's extend stage, the isotropic one -min(p) of iso_ext's, and
    what Rumpf's estimate needs: nu and C where the extension starts, and the mean overlap at the
    end of the 1e8 Pa step (the consolidation; delta_max of a typical contact)."""
    hits = sorted(glob.glob(os.path.join(run, "deviatoric", "compaction_phi*.csv")))
    if not hits:
        raise CurveError(f"{run}: no deviatoric/compaction_phi*.csv (run data/scenes/powder_compaction.toml there)")
    c = read_curve(hits[0])
    prep = read_curve(os.path.join(run, "prep", "loose.csv"))
    out = {"run": run, "nu_loose": float(prep["nu"][-1]), "sigma_zz_loose_Pa": float(prep["sigma_zz_Pa"][-1]),
           "loose_error": float(prep["control_error_rel"][-1]),
           "load": stage_ends(c, "load_"), "unload": stage_ends(c, "unload_")}
    top = np.flatnonzero(c["stage"] == out["load"][-1][0])[-1]
    out["overlap_consolidated_rel"] = float(c["overlap_mean_rel"][top])
    out["sigma_consolidated_Pa"] = float(c["sigma_zz_Pa"][top])
    ext = np.flatnonzero(c["stage"] == "extend")
    out["nu_ext"], out["C_ext"] = float(c["nu"][ext[0]]), float(c["C"][ext[0]])
    out["tensile_uniaxial_Pa"] = float(-c["sigma_zz_Pa"][ext].min())
    iso = sorted(glob.glob(os.path.join(run, "deviatoric", "iso_ext_phi*.csv")))
    if iso:
        ci = read_curve(iso[0])
        e = np.flatnonzero(ci["stage"] == "extend")
        out["tensile_isotropic_Pa"] = float(-ci["p_Pa"][e].min())
        out["C_ext_iso"], out["nu_ext_iso"] = float(ci["C"][e[0]]), float(ci["nu"][e[0]])
    return out


# ------------------------------------------------------------------------------------------
# Output


def fmt(v, e=None):
    if not math.isfinite(v):
        return "∞" if v == math.inf else "–"
    if e is None or not math.isfinite(e) or e <= 0:
        return f"{v:.3g}"
    digits = max(0, 1 - int(math.floor(math.log10(e))))
    return f"{v:.{digits}f} ± {e:.{digits}f}" if abs(v) < 1e4 else f"{v:.3g} ± {e:.2g}"


def write_level(members, out, label, extra=None):
    """members.csv (one row per packing) and summary.json of one adhesion level."""
    cols = ["run", "sigma_pre_Pa", "tau_pre_Pa", "sigma_1_Pa", "sigma_2_Pa", "sigma_c_Pa", "c_Pa", "phi_lin_deg",
            "phi_e_deg", "ffc", "class", "nu", "C", "overlap_mean_rel", "servo_error_mean", "servo_error_max", "steps",
            "wall_s"]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols + ["failure_points_sigma_n_Pa:tau_f_Pa"])
    for r in members:
        w.writerow([r[c] if isinstance(r[c], str) else f"{r[c]:.6g}" for c in cols] +
                   [" ".join(f"{a:.6g}:{b:.6g}" for a, b in r["points"])])
    write_atomic(os.path.join(out, "members.csv"), buf.getvalue())
    s = summarise(members, label, extra)
    write_json_atomic(os.path.join(out, "summary.json"), {"summary": s, "members": members})
    return s


TABLE_COLS = ("label", "K", "Bo", "Bo_ci95", "sigma_pre_Pa", "sigma_1_Pa", "sigma_1_Pa_ci95", "sigma_c_Pa",
              "sigma_c_Pa_ci95", "ffc", "ffc_lo", "ffc_hi", "class", "phi_e_deg", "phi_e_deg_ci95", "phi_lin_deg",
              "phi_lin_deg_ci95", "c_Pa", "c_Pa_ci95", "nu", "C", "servo_error_mean", "servo_error_max", "steps", "wall_s")


def write_table(summaries, out):
    """table.csv (units in the header) and table.md (for people) over adhesion levels."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(TABLE_COLS)
    for s in summaries:
        w.writerow([s.get(c, "") if isinstance(s.get(c, ""), str) else f"{s.get(c, math.nan):.6g}"
                    for c in TABLE_COLS])
    write_atomic(os.path.join(out, "table.csv"), buf.getvalue())
    lines = ["| level | kc/k1 | σ_pre [MPa] | K | Bo | σ₁ [MPa] | σ_c [MPa] | ffc (95 %) | class | φ_e [°] | φ_lin [°] | "
             "c [MPa] | ν | C |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in summaries:
        ffc = f"{fmt(s['ffc'])} ({fmt(s['ffc_lo'])}–{fmt(s['ffc_hi'])})"
        lines.append(f"| {s['label']} | {s.get('kc_over_k1', math.nan):g} | {s['sigma_pre_Pa'] / 1e6:.0f} | {s['K']} | "
                     f"{fmt(s.get('Bo', math.nan), s.get('Bo_ci95'))} | "
                     f"{fmt(s['sigma_1_Pa'] / 1e6, s['sigma_1_Pa_ci95'] / 1e6)} | "
                     f"{fmt(s['sigma_c_Pa'] / 1e6, s['sigma_c_Pa_ci95'] / 1e6)} | {ffc} | {s['class']} | "
                     f"{fmt(s['phi_e_deg'], s['phi_e_deg_ci95'])} | {fmt(s['phi_lin_deg'], s['phi_lin_deg_ci95'])} | "
                     f"{fmt(s['c_Pa'] / 1e6, s['c_Pa_ci95'] / 1e6)} | {fmt(s['nu'], s['nu_ci95'])} | "
                     f"{fmt(s['C'], s['C_ci95'])} |")
    write_atomic(os.path.join(out, "table.md"), "\n".join(lines) + "\n")


def plot_loci(summaries, out):
    """Yield loci (each packing's failure points, the mean locus) with the two Mohr circles."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    ncol = min(4, len(summaries))
    nrow = -(-len(summaries) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.0 * nrow), squeeze=False)
    for ax in axes.flat[len(summaries):]:
        ax.set_visible(False)
    for ax, s in zip(axes.flat, summaries):
        pts = np.array([p for m in s["members"] for p in m["points"]]) / 1e6
        ax.plot(pts[:, 0], pts[:, 1], "o", ms=3, color="0.5", label="shear to failure")
        pre = np.array([(m["sigma_pre_Pa"], m["tau_pre_Pa"]) for m in s["members"]]) / 1e6
        ax.plot(pre[:, 0], pre[:, 1], "s", ms=4, color="k", label="pre-shear")
        c, phi = s["c_Pa"] / 1e6, math.radians(s["phi_lin_deg"])
        x = np.linspace(0, s["sigma_pre_Pa"] / 1e6, 50)
        ax.plot(x, c + x * math.tan(phi), "C0-", label="yield locus (mean)")
        th = np.linspace(0, math.pi, 100)
        sc = s["sigma_c_Pa"] / 1e6
        ax.plot(sc / 2 * (1 + np.cos(th)), sc / 2 * np.sin(th), "C1-", label=f"σ_c = {sc:.3g} MPa")
        s1, s2 = s["sigma_1_Pa"] / 1e6, s["sigma_2_mean_Pa"] / 1e6
        ax.plot((s1 + s2) / 2 + (s1 - s2) / 2 * np.cos(th), (s1 - s2) / 2 * np.sin(th), "C3-",
                label=f"σ₁ = {s1:.3g} MPa")
        ax.plot([0, s1], [0, s1 * math.tan(math.radians(s["phi_e_deg"]))], "k:", lw=0.8, label="φ_e")
        ax.set_xlim(0, s1 * 1.05)
        ax.set_ylim(0, s1 * 0.6)
        ax.set_aspect("equal")
        ax.set_xlabel("σ [MPa]")
        ax.set_ylabel("τ [MPa]")
        ax.set_title(f"{s['label']} (kc/k1 = {s.get('kc_over_k1', math.nan):g}): ffc = {fmt(s['ffc'])}", fontsize=9)
        ax.legend(fontsize=6, loc="upper left")
    fig.tight_layout()
    write_figure(fig, os.path.join(out, "yield_loci"))


def plot_flow_function(summaries, out):
    """sigma_c against sigma_1 with the class boundaries ffc = 1, 2, 4, 10."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5, 4.2))
    top = max(s["sigma_1_Pa"] for s in summaries) / 1e6 * 1.2
    ytop = top / 1.5
    x = np.linspace(0, top, 10)
    for bound, name in CLASSES[:-1]:
        ax.plot(x, x / bound, color="0.7", lw=0.8)
        xl = min(top, ytop * bound) * 0.97
        ax.text(xl, xl / bound, f"ffc = {bound:g}", fontsize=7, ha="right", va="bottom", color="0.4")
    for s in summaries:
        ax.errorbar(s["sigma_1_Pa"] / 1e6, s["sigma_c_Pa"] / 1e6, xerr=s["sigma_1_Pa_ci95"] / 1e6,
                    yerr=s["sigma_c_Pa_ci95"] / 1e6, fmt="o", capsize=3,
                    label=f"{s['label']}: ffc {fmt(s['ffc'])} ({s['class']})")
    groups = {}
    for s in summaries:   # one adhesion at several pre-shear stresses: the flow function as a line
        groups.setdefault(s.get("kc_over_k1"), []).append((s["sigma_1_Pa"] / 1e6, s["sigma_c_Pa"] / 1e6))
    for kc, pts in groups.items():
        if len(pts) > 1:
            pts.sort()
            ax.plot(*zip(*pts), color="0.3", lw=0.8, ls="--")
    ax.set_xlim(0, top)
    ax.set_ylim(0, ytop)
    ax.set_xlabel("major consolidation stress σ₁ [MPa]")
    ax.set_ylabel("unconfined yield strength σ_c [MPa]")
    ax.set_title("flow function (95 % intervals over packings)", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    write_figure(fig, os.path.join(out, "flow_function"))


def level_extra(members, scene_keys):
    """The Bond number of a level from its runs: the pull-off force of a contact at the mean
    overlap of the pre-shear, over sigma_pre d^2 (d the mean diameter)."""
    k1, kp, kc, phi_f, d = (scene_keys[k] for k in ("k1", "kp", "kc", "phi_f", "d"))
    bos = []
    for m in members:
        r = d / 2
        f = luding_pull_off(k1, kp, kc, phi_f, r / 2, m["overlap_mean_rel"] * r)
        bos.append(bond_number(f, m["sigma_pre_Pa"], d))
    mean, h, _, _ = mean_ci(bos)
    return {"Bo": mean, "Bo_ci95": h, "kc_over_k1": kc / k1}


def finished(run):
    """A run folder whose manifest.json says complete (runs still going are left out)."""
    try:
        with open(os.path.join(run, "manifest.json")) as fh:
            return json.load(fh).get("complete") is True
    except (OSError, ValueError):
        return False


def compaction_levels(level_dirs, out):
    """Compaction and tensile strength over packings, one level (adhesion) per folder of run
    folders (LEVEL/s*/): compaction.csv, compaction.md and compaction.{png,svg}."""
    rows, per_level = [], {}
    for lvl in level_dirs:
        runs = sorted(r for r in glob.glob(os.path.join(lvl, "*")) if finished(r))
        res = [compaction_tensile(r) for r in runs]
        if not res:
            raise CurveError(f"{lvl}: no run folders with a compaction curve")
        keys = scene_luding(runs[0])
        name = os.path.basename(os.path.normpath(lvl))
        per_level[name] = res
        row = {"label": name, "K": len(res), "kc_over_k1": keys["kc"] / keys["k1"]}
        for q in ("nu_loose", "tensile_uniaxial_Pa", "tensile_isotropic_Pa", "C_ext", "C_ext_iso", "nu_ext",
                  "overlap_consolidated_rel"):
            row[q], row[q + "_ci95"], _, _ = mean_ci([r.get(q, math.nan) for r in res])
        for key in ("load", "unload"):
            for k, step in enumerate(res[0][key]):
                m, h, _, _ = mean_ci([r[key][k][2] for r in res])
                row[f"nu_{step[0]}"], row[f"nu_{step[0]}_ci95"] = m, h
        # Rumpf with the pull-off force at the mean consolidation overlap
        r_mean = keys["d"] / 2
        f = [luding_pull_off(keys["k1"], keys["kp"], keys["kc"], keys["phi_f"], r_mean / 2,
                             r["overlap_consolidated_rel"] * r_mean) for r in res]
        row["f_pull_N"] = float(np.mean(f))
        row["Bo_consolidation"] = bond_number(row["f_pull_N"], float(np.mean([r["sigma_consolidated_Pa"] for r in res])),
                                              keys["d"])
        rumpf_u = [rumpf_tensile_strength(r["nu_ext"], r["C_ext"], fi, keys["d"]) for r, fi in zip(res, f)]
        rumpf_i = [rumpf_tensile_strength(r["nu_ext_iso"], r["C_ext_iso"], fi, keys["d"]) for r, fi in zip(res, f)
                   if "nu_ext_iso" in r]
        row["rumpf_uniaxial_Pa"], row["rumpf_uniaxial_Pa_ci95"], _, _ = mean_ci(rumpf_u)
        row["rumpf_isotropic_Pa"], row["rumpf_isotropic_Pa_ci95"], _, _ = mean_ci(rumpf_i)
        rows.append(row)
    cols = list(rows[0].keys())
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([r[c] if isinstance(r[c], str) else f"{r[c]:.6g}" for c in cols])
    write_atomic(os.path.join(out, "compaction.csv"), buf.getvalue())
    steps = [k for k in cols if k.startswith("nu_load_") or k.startswith("nu_unload_")]
    steps = [k for k in steps if not k.endswith("_ci95")]
    lines = ["| level | K | ν loose (σ_zz = 1 MPa, prep) | " + " | ".join(
                 ("ν at " + k[3:].replace("_", " ") + " Pa") for k in steps) + " |",
             "|---|---|---|" + "---|" * len(steps)]
    for r in rows:
        lines.append(f"| {r['label']} | {r['K']} | {fmt(r['nu_loose'], r['nu_loose_ci95'])} | " +
                     " | ".join(fmt(r[k], r[k + '_ci95']) for k in steps) + " |")
    lines += ["", "| level | K | Bo (at 100 MPa) | C at extension | σ_t uniaxial [MPa] | Rumpf uniaxial [MPa] | "
              "σ_t isotropic [MPa] | Rumpf isotropic [MPa] |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['label']} | {r['K']} | {fmt(r['Bo_consolidation'])} | {fmt(r['C_ext'], r['C_ext_ci95'])} | "
                     f"{fmt(r['tensile_uniaxial_Pa'] / 1e6, r['tensile_uniaxial_Pa_ci95'] / 1e6)} | "
                     f"{fmt(r['rumpf_uniaxial_Pa'] / 1e6, r['rumpf_uniaxial_Pa_ci95'] / 1e6)} | "
                     f"{fmt(r['tensile_isotropic_Pa'] / 1e6, r['tensile_isotropic_Pa_ci95'] / 1e6)} | "
                     f"{fmt(r['rumpf_isotropic_Pa'] / 1e6, r['rumpf_isotropic_Pa_ci95'] / 1e6)} |")
    write_atomic(os.path.join(out, "compaction.md"), "\n".join(lines) + "\n")
    plot_compaction(per_level, out)
    return rows


def plot_compaction(per_level, out):
    """nu against sigma_zz at rest on each load and unload step, mean and 95 % interval per level."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5.2, 4))
    for k, (name, res) in enumerate(per_level.items()):
        for key, style in (("load", "-o"), ("unload", "--s")):
            sig = np.array([[st[1] for st in r[key]] for r in res]).mean(axis=0) / 1e6
            nus = np.array([[st[2] for st in r[key]] for r in res])
            m = nus.mean(axis=0)
            h = [mean_ci(nus[:, j])[1] for j in range(nus.shape[1])]
            ax.errorbar(sig, m, yerr=np.nan_to_num(h), fmt=style, color=f"C{k}", ms=4, capsize=2,
                        label=f"{name} {key}")
        loose = np.array([(r["sigma_zz_loose_Pa"], r["nu_loose"]) for r in res])
        ax.plot(loose[:, 0].mean() / 1e6, loose[:, 1].mean(), "^", color=f"C{k}", ms=6)
    ax.set_xscale("log")
    ax.set_xlabel("σ_zz [MPa] (confined: x, y fixed)")
    ax.set_ylabel("volume fraction ν")
    ax.set_title("confined compaction in load steps, at rest (▲: the loose state)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    write_figure(fig, os.path.join(out, "compaction"))


# ------------------------------------------------------------------------------------------
# The time step against accuracy and cost (the adhesive runs' dt chart, docs/powders.md)

DT_QUANTITIES = (("inv_ffc", "1/ffc", 1.0), ("sigma_c_Pa", "σ_c [MPa]", 1e-6), ("sigma_1_Pa", "σ₁ [MPa]", 1e-6),
                 ("phi_e_deg", "φ_e [°]", 1.0), ("c_Pa", "c [MPa]", 1e-6), ("nu", "ν", 1.0))


def welch_diff(a, b):
    """(mean(a) - mean(b), half-width of its 95 % Welch interval) of two samples (NaN if either has < 2)."""
    a = np.asarray([x for x in a if math.isfinite(x)], float)
    b = np.asarray([x for x in b if math.isfinite(x)], float)
    if a.size < 2 or b.size < 2:
        return math.nan, math.nan
    va, vb = a.var(ddof=1) / a.size, b.var(ddof=1) / b.size
    se = math.sqrt(va + vb)
    dof = (va + vb) ** 2 / (va * va / (a.size - 1) + vb * vb / (b.size - 1)) if se > 0 else a.size + b.size - 2
    return float(a.mean() - b.mean()), float(stats.t.ppf(0.975, dof) * se)


VARY = {"dt": ("integration", "dt_over_tc", 0.02, "dt/t_c"),
        "rate": ("protocol", "deviatoric_rate_tc", 1e-4, "rate·t_c")}


def dt_rows(levels, reference=None, vary="dt"):
    """{name: [run folders]} of one adhesion level at several time steps (or rates: vary =
    "rate"): per value the mean and 95 % interval of each DT_QUANTITIES entry, its difference to
    the reference (the smallest value, unless given) with a Welch interval, whether its mean lies
    outside the reference's 95 % interval, the inertial numbers and the cost (steps, wall and CPU
    time) per packing. Runs that stopped early (a failed_*.ckpt: the run blew up) count as
    failed; runs without a complete manifest otherwise (still running) are left out."""
    section, key, default, _ = VARY[vary]
    per = {}
    for name, runs in levels.items():
        ok = [r for r in runs if finished(r)]
        rows = [analyse_run(r) for r in ok]
        x = scene_value(runs[0], section, key, default)
        n = scene_value(runs[0], "particles", "count", 500)
        failed = sum(1 for r in runs if glob.glob(os.path.join(r, "failed_*.ckpt")))
        per[name] = {"x": x, "members": rows, "failed": failed, "N": n}
    usable = {k: v for k, v in per.items() if len(v["members"]) >= 2}
    ref = reference or min(usable, key=lambda k: usable[k]["x"])
    out = []
    for name, v in sorted(per.items(), key=lambda kv: -kv[1]["x"]):
        row = {"label": name, "x": v["x"], "x_name": VARY[vary][3], "K": len(v["members"]), "failed": v["failed"],
               "reference": name == ref, "N": v["N"]}
        for q in ("steps", "wall_s", "cpu_s", "I_preshear", "I_shear") + tuple(q for q, _, _ in DT_QUANTITIES):
            vals = [m.get(q, math.nan) for m in v["members"]]
            ref_vals = [m.get(q, math.nan) for m in per[ref]["members"]]
            row[q], row[q + "_ci95"], _, _ = mean_ci(vals)
            rm, rh, _, _ = mean_ci(ref_vals)
            row[q + "_diff"], row[q + "_diff_ci95"] = welch_diff(vals, ref_vals)
            row[q + "_outside"] = bool(math.isfinite(rh) and abs(row[q] - rm) > rh)
        out.append(row)
    return out, ref


def write_dt_chart(rows, ref, out, level_text):
    """dt_cost.csv (units in the header), dt_cost.md and dt_cost.{png,svg}."""
    cols = ["label", "x_name", "x", "K", "failed"] + [c for q, _, _ in DT_QUANTITIES for c in
                                                     (q, q + "_ci95", q + "_diff", q + "_diff_ci95", q + "_outside")]
    cols += ["I_preshear", "I_shear", "steps", "wall_s", "wall_s_ci95", "cpu_s", "cpu_s_ci95"]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([r[c] if isinstance(r[c], (str, bool)) else f"{r[c]:.6g}" for c in cols])
    write_atomic(os.path.join(out, "dt_cost.csv"), buf.getvalue())
    xn = rows[0]["x_name"]
    head = (f"| {xn} | K | " + " | ".join(lbl for _, lbl, _ in DT_QUANTITIES) +
            " | I pre-shear | I shear | steps per packing | wall [s] | CPU [s] |")
    lines = [f"Level: {level_text}; reference {xn} = {next(r['x'] for r in rows if r['reference']):g}; "
             "± 95 % over packings; * the mean lies outside the reference's 95 % interval.", "", head,
             "|" + "---|" * (len(DT_QUANTITIES) + 7)]
    for r in rows:
        cells = []
        for q, _, scale in DT_QUANTITIES:
            cells.append(fmt(r[q] * scale, r[q + "_ci95"] * scale) + (" *" if r[q + "_outside"] else ""))
        fail = f" ({r['failed']} failed)" if r["failed"] else ""
        lines.append(f"| {r['x']:g}{' (ref)' if r['reference'] else ''} | {r['K']}{fail} | " +
                     " | ".join(cells) + f" | {fmt(r['I_preshear'])} | {fmt(r['I_shear'])} | {fmt(r['steps'])} | "
                     f"{fmt(r['wall_s'], r['wall_s_ci95'])} | "
                     f"{fmt(r['cpu_s'], r['cpu_s_ci95'])} |")
    write_atomic(os.path.join(out, "dt_cost.md"), "\n".join(lines) + "\n")
    plot_dt_chart(rows, out, level_text)


def plot_dt_chart(rows, out, level_text):
    """Left: each quantity over its reference value against dt (95 % intervals; grey band: the
    reference's interval of 1/ffc). Right: steps and wall time per packing against dt."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.transforms
    failed = [r for r in rows if r["K"] == 0 and r["failed"] > 0]
    rows = [r for r in rows if r["K"] > 0]
    ref = next(r for r in rows if r["reference"])
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    dts = np.array([r["x"] for r in rows])
    shown = [d for d in DT_QUANTITIES if d[0] != "c_Pa"]
    for k, (q, lbl, _) in enumerate(shown):
        y = np.array([r[q] for r in rows]) / ref[q]
        e = np.nan_to_num(np.array([r[q + "_ci95"] for r in rows]) / abs(ref[q]))
        ax.errorbar(dts * (1 + 0.025 * (k - 2)), y, yerr=e, fmt="o-", ms=4, capsize=2, label=lbl)
        if k == 0:
            h = ref[q + "_ci95"] / ref[q]
            ax.axhspan(1 - h, 1 + h, color="0.85", zorder=0, label="reference 95 % (1/ffc)")
    ax.axhline(1, color="0.5", lw=0.8)
    for r in failed:
        ax.axvline(r["x"], color="C3", ls=":", lw=1)
        ax.text(r["x"], 0.03, f"blew up ({r['failed']} of {r['failed']}) ", color="C3", fontsize=7, va="bottom",
                ha="right", transform=matplotlib.transforms.blended_transform_factory(ax.transData, ax.transAxes))
    ax.set_xscale("log")
    ax.set_xlabel(rows[0]["x_name"])
    ax.set_ylabel("value / value at the reference")
    ax.set_title(f"accuracy: {level_text}", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    bx.loglog(dts, [r["steps"] * r["N"] for r in rows], "ks-", label="particle-steps per packing")
    bx.set_xlabel(rows[0]["x_name"])
    bx.set_ylabel("particle-steps per packing")
    b2 = bx.twinx()
    b2.errorbar(dts, [r["wall_s"] for r in rows], yerr=np.nan_to_num([r["wall_s_ci95"] for r in rows]), fmt="o",
                color="C3", capsize=2, label="wall time (loaded machine)")
    b2.errorbar(dts, [r["cpu_s"] for r in rows], yerr=np.nan_to_num([r["cpu_s_ci95"] for r in rows]), fmt="^",
                color="C1", capsize=2, label="CPU time (user + sys)")
    b2.legend(loc="lower left", fontsize=7)
    b2.set_yscale("log")
    b2.set_ylabel("time per packing [s]", color="C3")
    bx.set_title(f"cost per packing (N = {ref['N']:.0f})", fontsize=9)
    bx.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    write_figure(fig, os.path.join(out, "dt_cost"))


# ------------------------------------------------------------------------------------------
# Friction and cohesion against the Bond number, one series per contact friction


def bond_rows(table_dirs, labels):
    """One row per level of each table folder (its levels/*/summary.json): the series label, Bo,
    the steady pre-shear friction tau_pre/sigma_pre, phi_lin, phi_e and c/sigma_pre, with 95 %
    intervals over packings (the ratio's from the packings' ratios)."""
    rows = []
    for folder, label in zip(table_dirs, labels):
        for path in sorted(glob.glob(os.path.join(folder, "levels", "*", "summary.json"))):
            with open(path) as fh:
                js = json.load(fh)
            s, mem = js["summary"], js["members"]
            row = {"series": label, "level": s["label"], "K": s["K"], "kc_over_k1": s.get("kc_over_k1"),
                   "sigma_pre_Pa": s["sigma_pre_Pa"], "Bo": s.get("Bo"), "Bo_ci95": s.get("Bo_ci95")}
            for key, vals in (("mu_steady", [m["tau_pre_Pa"] / m["sigma_pre_Pa"] for m in mem]),
                              ("c_over_sigma_pre", [m["c_Pa"] / m["sigma_pre_Pa"] for m in mem]),
                              ("phi_lin_deg", [m["phi_lin_deg"] for m in mem]),
                              ("phi_e_deg", [m["phi_e_deg"] for m in mem]),
                              ("inv_ffc", [m["inv_ffc"] for m in mem])):
                row[key], row[key + "_ci95"], _, _ = mean_ci(vals)
            rows.append({k: (math.nan if v is None else v) for k, v in row.items()})
    order = {label: k for k, label in enumerate(labels)}
    return sorted(rows, key=lambda r: (order[r["series"]], r["Bo"] if math.isfinite(r["Bo"]) else -1.0))


def write_bond(rows, out):
    """bond.csv, bond.md and bond.{png,svg}: friction and cohesion against Bo per series."""
    cols = list(rows[0].keys())
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([r[c] if isinstance(r[c], str) else f"{r[c]:.6g}" for c in cols])
    write_atomic(os.path.join(out, "bond.csv"), buf.getvalue())
    lines = ["| series | level | σ_pre [MPa] | K | Bo | τ_pre/σ_pre | φ_lin [°] | φ_e [°] | c/σ_pre | ffc |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ffc = 1 / r["inv_ffc"] if r["inv_ffc"] > 0 else math.inf
        lines.append(f"| {r['series']} | {r['level']} | {r['sigma_pre_Pa'] / 1e6:.0f} | {r['K']} | "
                     f"{fmt(r['Bo'], r['Bo_ci95'])} | {fmt(r['mu_steady'], r['mu_steady_ci95'])} | "
                     f"{fmt(r['phi_lin_deg'], r['phi_lin_deg_ci95'])} | {fmt(r['phi_e_deg'], r['phi_e_deg_ci95'])} | "
                     f"{fmt(r['c_over_sigma_pre'], r['c_over_sigma_pre_ci95'])} | {fmt(ffc)} |")
    write_atomic(os.path.join(out, "bond.md"), "\n".join(lines) + "\n")
    plot_bond(rows, out)


def plot_bond(rows, out):
    """Macroscopic friction (steady tau/sigma, tan phi_lin) and cohesion c/sigma_pre against Bo
    (log axis; Bo = 0 drawn at the left edge)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    pos = [r["Bo"] for r in rows if r["Bo"] > 0]
    left = min(pos) / 3 if pos else 1e-2
    for k, series in enumerate(dict.fromkeys(r["series"] for r in rows)):
        sr = sorted((r for r in rows if r["series"] == series), key=lambda r: r["Bo"])
        bo = np.array([max(r["Bo"], left) for r in sr])
        for key, style, name in (("mu_steady", "o-", "τ_pre/σ_pre (steady)"), ("phi_lin_deg", "s--", "tan φ_lin")):
            y = np.array([r[key] for r in sr])
            e = np.nan_to_num([r[key + "_ci95"] for r in sr])
            if key == "phi_lin_deg":
                y, e = np.tan(np.radians(y)), np.nan_to_num(e * np.pi / 180 / np.cos(np.radians(y)) ** 2)
            ax.errorbar(bo, y, yerr=e, fmt=style, color=f"C{k}", ms=4, capsize=2, label=f"{series}: {name}")
        bx.errorbar(bo, [r["c_over_sigma_pre"] for r in sr], yerr=np.nan_to_num([r["c_over_sigma_pre_ci95"] for r in sr]),
                    fmt="o-", color=f"C{k}", ms=4, capsize=2, label=series)
    for a in (ax, bx):
        a.set_xscale("log")
        a.axvline(left * 1.5, color="0.8", lw=0.8)
        a.set_xlabel("Bo = f_pull(δ̄)/(σ_pre d²)  (leftmost: Bo = 0)")
    ax.set_ylabel("macroscopic friction")
    bx.set_ylabel("cohesion c / σ_pre")
    bx.axhline(0, color="0.5", lw=0.8)
    ax.legend(fontsize=7)
    bx.legend(fontsize=7)
    fig.tight_layout()
    write_figure(fig, os.path.join(out, "bond"))


def sweep_levels(folder):
    """{row name: [member run folders]} of a `dem ensemble --sweep` folder (rows/NAME/members/mKKK)
    or of a plain ensemble folder (members/mKKK: one level named after the folder)."""
    rows = sorted(glob.glob(os.path.join(folder, "rows", "*")))
    if not rows:
        rows = [folder]
    out = {}
    for r in rows:
        members = sorted(m for m in glob.glob(os.path.join(r, "members", "m*")) if glob.glob(
            os.path.join(m, "deviatoric", "shear_tester_phi*.csv")))
        if members:
            out[os.path.basename(os.path.normpath(r))] = members
    if not out:
        raise CurveError(f"{folder}: no rows/*/members/m*/deviatoric/shear_tester_phi*.csv (a dem ensemble of "
                         "data/scenes/shear_tester.toml)")
    return out


def scene_luding(run):
    """k1, kp, kc, phi_f and the mean diameter of a run folder's scene.toml (for the Bond number)."""
    import tomllib
    with open(os.path.join(run, "scene.toml"), "rb") as fh:
        sc = tomllib.load(fh)
    c, p = sc.get("contact", {}), sc.get("particles", {})
    k1 = float(c.get("stiffness_N_m", 1e8))
    return {"k1": k1, "kp": float(c.get("luding_kp_N_m", 5 * k1)), "kc": float(c.get("luding_kc_N_m", 0.0)),
            "phi_f": float(c.get("luding_plasticity_depth", 0.05)),
            "d": float(p.get("radius_min_m", 0.5e-3)) + float(p.get("radius_max_m", 1.5e-3))}


def analyse_sweep(folder, out):
    """Every row of a sweep: its level folder under out/levels/NAME, then the table and plots."""
    return analyse_levels(sweep_levels(folder), out)


TRIM_COLUMNS = ("step", "eps_d_accumulated", "sigma_zz_Pa", "sigma_xz_Pa", "target_zz_Pa", "control_error_rel", "nu",
                "C", "overlap_mean_rel", "inertial_number", "stage")


def trim_curve(src, dst, columns=TRIM_COLUMNS):
    """A copy of a curve with its comment lines and only `columns` (for data/)."""
    with open(src) as fh:
        lines = fh.read().splitlines()
    comments = [ln for ln in lines if ln.startswith("#")]
    rows = list(csv.reader(ln for ln in lines if ln and not ln.startswith("#")))
    keep = [rows[0].index(c) for c in columns if c in rows[0]]
    buf = io.StringIO()
    buf.write("\n".join(comments) + "\n")
    w = csv.writer(buf, lineterminator="\n")
    for r in rows:
        w.writerow([r[k] for k in keep])
    write_atomic(dst, buf.getvalue())


def analyse_levels(levels, out):
    """{name: [run folders]}: each level's members.csv and summary.json under out/levels/NAME,
    then table.csv, table.md, yield_loci.{png,svg} and flow_function.{png,svg} in out."""
    sums = []
    for name, members in levels.items():
        if not members:
            continue
        rows = [analyse_run(m) for m in members]
        keys = scene_luding(members[0])
        s = write_level(rows, os.path.join(out, "levels", name), name, level_extra(rows, keys))
        trim_curve(find_curve(members[0]), os.path.join(out, "levels", name, "curve_first_packing.csv"))
        s["members"] = rows
        s["sigma_2_mean_Pa"] = float(np.mean([m["sigma_2_Pa"] for m in rows]))
        sums.append(s)
    sums.sort(key=lambda s: s.get("kc_over_k1", 0))
    write_table(sums, out)
    plot_loci(sums, out)
    plot_flow_function(sums, out)
    return sums


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", help="run folders (or curves) of one level; with --table: level folders")
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--label", default="", help="the level's name (e.g. kc/k1=0.5)")
    ap.add_argument("--table", action="store_true", help="collect level folders (summary.json) into the table and plots")
    ap.add_argument("--sweep", action="store_true", help="RUN is a `dem ensemble --sweep` folder: every row a level")
    ap.add_argument("--compaction", action="store_true",
                    help="RUNS are level folders of powder_compaction.toml runs (LEVEL/s*/): compaction and tensile tables")
    ap.add_argument("--levels", action="store_true",
                    help="RUNS are level folders of shear_tester.toml runs (LEVEL/s*/): every level, then the table")
    ap.add_argument("--dt-chart", action="store_true",
                    help="RUNS are level folders of one adhesion at several dt (LEVEL/s*/): the dt/cost chart")
    ap.add_argument("--reference", default="", help="with --dt-chart: the level folder name of the reference dt "
                    "(default: the finest)")
    ap.add_argument("--vary", default="dt", choices=sorted(VARY),
                    help="with --dt-chart: what differs between the level folders (dt or the shear rate)")
    ap.add_argument("--bond", action="store_true",
                    help="RUNS are table folders (levels/*/summary.json), one per series: friction, cohesion against Bo")
    ap.add_argument("--series", default="", help="with --bond: comma-separated series labels, one per folder")
    ap.add_argument("--luding", default="", help="k1,kp,kc,phi_f,d (N/m, -, m) for the Bond number of a level")
    a = ap.parse_args(argv)
    try:
        if a.compaction:
            compaction_levels(a.runs, a.out)
            print(open(os.path.join(a.out, "compaction.md")).read())
            return 0
        if a.dt_chart:
            levels = {os.path.basename(os.path.normpath(d)): sorted(
                r for r in glob.glob(os.path.join(d, "*")) if os.path.isdir(r)) for d in a.runs}
            rows, ref = dt_rows(levels, a.reference or None, a.vary)
            write_dt_chart(rows, ref, a.out, a.label or ref)
            print(open(os.path.join(a.out, "dt_cost.md")).read())
            return 0
        if a.bond:
            labels = a.series.split(",") if a.series else [os.path.basename(os.path.normpath(d)) for d in a.runs]
            if len(labels) != len(a.runs):
                raise ValueError(f"--series has {len(labels)} labels for {len(a.runs)} folders: give one per folder")
            write_bond(bond_rows(a.runs, labels), a.out)
            print(open(os.path.join(a.out, "bond.md")).read())
            return 0
        if a.levels:
            analyse_levels({os.path.basename(os.path.normpath(d)): sorted(
                r for r in glob.glob(os.path.join(d, "*")) if finished(r)) for d in a.runs}, a.out)
            print(open(os.path.join(a.out, "table.md")).read())
            return 0
        if a.sweep:
            analyse_sweep(a.runs[0], a.out)
            print(open(os.path.join(a.out, "table.md")).read())
            return 0
        if a.table:
            sums = []
            for lvl in a.runs:
                with open(os.path.join(lvl, "summary.json")) as fh:
                    js = json.load(fh)
                s = js["summary"]
                s["members"] = js["members"]
                s["sigma_2_mean_Pa"] = float(np.mean([m["sigma_2_Pa"] for m in js["members"]]))
                for k, v in list(s.items()):
                    if v is None:
                        s[k] = math.nan
                sums.append(s)
            write_table(sums, a.out)
            plot_loci(sums, a.out)
            plot_flow_function(sums, a.out)
            print(open(os.path.join(a.out, "table.md")).read())
            return 0
        members = [analyse_run(r) for r in a.runs]
        extra = None
        if a.luding:
            k1, kp, kc, phi_f, d = (float(x) for x in a.luding.split(","))
            extra = level_extra(members, {"k1": k1, "kp": kp, "kc": kc, "phi_f": phi_f, "d": d})
        s = write_level(members, a.out, a.label, extra)
        print(f"{a.label}: K = {s['K']}, sigma_1 = {fmt(s['sigma_1_Pa'], s['sigma_1_Pa_ci95'])} Pa, "
              f"sigma_c = {fmt(s['sigma_c_Pa'], s['sigma_c_Pa_ci95'])} Pa, ffc = {fmt(s['ffc'])} "
              f"[{fmt(s['ffc_lo'])}, {fmt(s['ffc_hi'])}] ({s['class']}), phi_e = {fmt(s['phi_e_deg'], s['phi_e_deg_ci95'])}")
        return 0
    except (CurveError, ValueError, OSError, KeyError) as e:
        print(f"demkit.powders: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
