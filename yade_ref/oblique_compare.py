#!/usr/bin/env python3
"""Oblique two-sphere impacts with friction in both codes: `dem collide --angle-deg A` against
`yade_ref/collision.py --angle-deg A` (ViscElMat kn = 2k, cn = 2 gamma, ks = 2 k_t, frictionAngle = atan(mu);
a non-periodic pair, so the shift-velocity sign of the ViscEl law does not enter), with the rigid-body
theory of gross sliding (Chung & Ooi 2011, Test 4, in relative velocities): for tan(theta) > 7/2 mu (1 + e_n),
e_t = 1 - mu (1 + e_n) / tan(theta).

    /usr/bin/python3 yade_ref/oblique_compare.py [--angles 10,30,45,60,80] [--out data/yade_friction/oblique.csv]
"""
import argparse
import json
import math
import os
import subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def ours(angle, mu, kt_ratio, dt_over_tc, r2):
    out = subprocess.run([os.path.join(ROOT, "build", "dem"), "collide", "--angle-deg", str(angle), "--r2", str(r2),
                          "--set", f"contact.friction={mu}", "--set", f"contact.tangential_stiffness_ratio={kt_ratio}",
                          "--set", "integration.integrator=symplectic_euler", "--set", f"integration.dt_over_tc={dt_over_tc}",
                          "--set", "particles.radius_max_m=0.0015"],
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def yade(angle, mu, kt_ratio, dt, r2):
    p = subprocess.run(["yade", "-n", "-x", "-j1", os.path.join(ROOT, "yade_ref", "collision.py"), "--angle-deg", str(angle),
                        "--r2", str(r2), "--friction", str(mu), "--kt-ratio", str(kt_ratio), "--dt", repr(dt)],
                       check=True, capture_output=True, text=True, cwd=ROOT)
    return json.loads([ln for ln in p.stdout.splitlines() if ln.startswith("{")][-1])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--angles", default="10,30,45,60,80")
    ap.add_argument("--mu", type=float, default=0.5)
    ap.add_argument("--kt-ratio", type=float, default=2.0 / 7.0)
    ap.add_argument("--dt-over-tc", type=float, default=0.002)
    ap.add_argument("--r2", type=float, default=5e-4)
    ap.add_argument("--out", default="")
    a = ap.parse_args()
    rows = []
    for ang in [float(x) for x in a.angles.split(",")]:
        o = ours(ang, a.mu, a.kt_ratio, a.dt_over_tc, a.r2)
        y = yade(ang, a.mu, a.kt_ratio, o["dt_s"], a.r2)      # ours' dt (t_c of the scene's smallest pair)
        en = o["normal_restitution"]
        t = math.tan(math.radians(ang))
        sliding = t > 3.5 * a.mu * (1 + en)
        theory = 1 - a.mu * (1 + en) / t if sliding else float("nan")
        rows.append(dict(angle_deg=ang, e_n_ours=en, e_n_yade=y["normal_restitution"],
                         e_t_ours=o["tangential_restitution"], e_t_yade=y["tangential_restitution"], e_t_theory=theory,
                         omega_ours=o["omega1_y_rad_s"], omega_yade=y["omega1_y_rad_s"],
                         omega0_ours=o["omega0_y_rad_s"], omega0_yade=y["omega0_y_rad_s"],
                         Jt_ours=o["tangential_impulse_Ns"], Jt_yade=y["tangential_impulse_Ns"]))
    keys = list(rows[0])
    lines = [",".join(keys)] + [",".join("%.12g" % r[k] for k in keys) for r in rows]
    print("\n".join(lines))
    if a.out:
        with open(a.out, "w") as fh:
            fh.write(f"# oblique impacts: mu={a.mu}, k_t/k={a.kt_ratio}, dt=t_c*{a.dt_over_tc}, r1=5e-4 m, r2={a.r2} m, "
                     "v0=0.1 m/s, gamma=1 kg/s; yade_ref/oblique_compare.py\n")
            fh.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
