#!/usr/bin/python3
"""Collects the adhesive compaction runs of bench/luding_compaction.sh: for each adhesion the
preparation curves (compress, cycle_loading, cycle_unloading) reduced to nu, p_Pa, C, and a
summary (the nu at which the isotropic unloading reaches p = 0: the density the packing keeps
when the pressure is taken away; the least p reached, tension when negative), plus the figure
docs/luding_compaction.{png,svg}.

    /usr/bin/python3 bench/luding_compaction.py RUNS_DIR OUT_DIR
"""
import os
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)
from demkit import curves  # noqa: E402
STAGES = ["compress", "cycle_loading", "cycle_unloading"]


def read_curve(path):
    c = curves.read_curve(path)
    return [{k: float(c[k][i]) for k in ("nu", "p_Pa", "C", "overlap_max_rel")} for i in range(len(c["nu"]))]


def nu_at_zero_pressure(rows):
    """The first nu of the unloading where p falls to zero (linear between samples), or None."""
    for a, b in zip(rows, rows[1:]):
        if a["p_Pa"] > 0 >= b["p_Pa"]:
            return a["nu"] + (b["nu"] - a["nu"]) * a["p_Pa"] / (a["p_Pa"] - b["p_Pa"])
    return None


def write_rows(path, header, rows):
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        fh.write(",".join(header) + "\n")
        for r in rows:
            fh.write(",".join(str(x) for x in r) + "\n")
    os.replace(tmp, path)


def main(runs, out):
    os.makedirs(out, exist_ok=True)
    runs_by_kc = sorted((float(d[2:]), os.path.join(runs, d)) for d in os.listdir(runs) if d.startswith("kc"))
    summary, curves = [], {}
    for kc, run in runs_by_kc:
        stages = {s: read_curve(os.path.join(run, "prep", s + ".csv")) for s in STAGES}
        curves[kc] = stages
        rows = [(s, r["nu"], r["p_Pa"], r["C"], r["overlap_max_rel"]) for s in STAGES for r in stages[s]]
        write_rows(os.path.join(out, f"kc{kc:g}_prep.csv"), ["stage", "nu", "p_Pa", "C", "overlap_max_rel"], rows)
        un = stages["cycle_unloading"]
        top = stages["cycle_loading"][-1]
        summary.append((kc, top["nu"], top["p_Pa"], top["C"], nu_at_zero_pressure(un), min(r["p_Pa"] for r in un),
                        un[-1]["nu"], un[-1]["p_Pa"], un[-1]["C"]))
    write_rows(os.path.join(out, "summary.csv"),
               ["kc_N_m", "nu_top", "p_top_Pa", "C_top", "nu_at_p0_unloading", "p_min_unloading_Pa", "nu_end",
                "p_end_Pa", "C_end"], summary)
    for s in summary:
        print("kc %-8g top nu %.4f p %.4g Pa C %.2f | unloading p=0 at nu %s, p_min %.4g Pa | end nu %.3f p %.4g Pa C %.2f"
              % (s[0], s[1], s[2], s[3], "%.4f" % s[4] if s[4] else "-", s[5], s[6], s[7], s[8]))
    figure(curves, runs_by_kc[0][1])


def figure(curves, run):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from demkit import figures as F
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    for k, (kc, st) in enumerate(sorted(curves.items())):
        load = st["compress"] + st["cycle_loading"]
        ax.plot([r["p_Pa"] / 1e6 for r in load], [r["nu"] for r in load], "-", color=f"C{k}",
                label=rf"$k_c/k_p = {kc / 5e8:g}$ loading")
        un = st["cycle_unloading"]
        ax.plot([r["p_Pa"] / 1e6 for r in un], [r["nu"] for r in un], "--", color=f"C{k}", label="unloading")
    ax.axvline(0, color="k", lw=0.5)
    ax.set_xscale("symlog", linthresh=1.0)
    ax.set_xlabel("p [MPa] (symmetric log; negative: tension)")
    ax.set_ylabel(r"volume fraction $\nu$")
    ax.set_title("isotropic compaction of 1000 adhesive frictional spheres (Luding, μ = 0.5)", fontsize=9)
    F.legend_if_any(ax, fontsize=7, loc="lower right")
    fig.tight_layout()
    F.save(fig, os.path.join(REPO, "docs", "luding_compaction"), run=run)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
