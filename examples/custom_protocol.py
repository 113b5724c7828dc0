#!/usr/bin/env python3
"""A protocol the scene format does not express, scripted with demtk (docs/python.md):

1. place 300 spheres at random and compress them isotropically until the coordination
   number C reaches 6 (a stop on our own criterion, checked by a callback),
2. relax at constant volume until the kinetic energy is 1e-6 of the elastic energy,
3. shear in D2 to eps_d = 0.25, recording the contact network at eps_d = 0.02, 0.05, 0.1 (a
   callback every strain increment), with a curve row every 0.002 of strain,
4. fit the saturating law to s_dev(eps_d) and report it only if the fit is usable (the tables' one
   rule: FitResult.usable; this small, fast-sheared packing fluctuates too much for the law, and
   the script says why); then the result that holds either way: the mean stress ratio over
   eps_d = 0.05-0.25 with its standard error from five strain blocks (model-free); save the
   networks (networks.npz) and the curve.

Run: /usr/bin/python3 examples/custom_protocol.py [--out DIR]   (about 20 s on one core)
"""
import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "build", "python"))   # where CMake builds demtk

import numpy as np  # noqa: E402

import demtk  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="runs/custom_protocol", help="output folder")
    ap.add_argument("--count", type=int, default=300)
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)

    scene = demtk.load_scene({
        "particles": {"count": args.count, "seed": 7},
        "integration": {"threads": 1},
        "protocol": {"compress_rate_tc": 3e-4, "deviatoric_rate_tc": 1e-4},
    })
    print(f"t_c = {scene.t_c:.4g} s, e = {scene.e:.4f}, dt = {scene.dt:.4g} s, "
          f"D2 rate = {scene.deviatoric_rate:.4g} 1/s")

    # 1. isotropic compression until C >= 6 (true strain rate -compress_rate on every axis)
    state = demtk.random_packing(scene, 0.3)
    eng = demtk.Engine(scene, state)
    compress = -scene.compress_rate * np.ones(3)

    def coordination_reached(e):
        m = e.measure()
        return m["C"] >= 6.0 or m["nu"] > 0.75

    eng.step(10 ** 8, velocity_gradient=compress, callback=coordination_reached, every=200)
    m = eng.measure()
    print(f"compression stopped at C = {m['C']:.3f}, phi = {m['nu']:.4f}, p = {m['p_Pa']:.4g} Pa "
          f"after {state.step} steps")

    # 2. relaxation in the fixed box
    def relaxed(e):
        m = e.measure()
        return m["E_kin_J"] < 1e-6 * max(m["E_pot_J"], 1e-30)

    eng.step(200000, callback=relaxed, every=500)
    m = eng.measure()
    print(f"relaxed: E_kin/E_pot = {m['E_kin_J'] / max(m['E_pot_J'], 1e-30):.3g}, C = {m['C']:.3f}, "
          f"step {state.step}")
    state.save_checkpoint(os.path.join(args.out, "relaxed.ckpt"), scene, "custom protocol, relaxed")

    # 3. D2 from here: strains from the stage start, as `dem mode` does
    state.zero_strain()
    eng = demtk.Engine(scene, state, forces_are_current=True)
    L = scene.velocity_gradient("D2")
    targets, eps_end = [0.02, 0.05, 0.1], 0.25   # the networks, and a curve long enough to saturate
    networks, rows = {}, [eng.measure(L).columns]

    def record(e):
        m = e.measure()
        rows.append(m.columns)
        if targets and m["eps_d"] >= targets[0] - 1e-12:
            c = e.contacts()
            networks[f"eps{targets.pop(0):.2f}"] = c
            print(f"  eps_d = {m['eps_d']:.4f}: {len(c['id_i'])} contacts, "
                  f"mean normal force {c['force_normal'].mean():.4g} N, s_dev = {m['s_dev']:.4f}")
        return m["eps_d"] >= eps_end

    eng.step(10 ** 8, velocity_gradient=L, callback=record, every_strain=0.002)

    # 4. the fit and the files
    eps = np.array([r["eps_d"] for r in rows])
    s_dev = np.array([r["s_dev"] for r in rows])
    fit = demtk.fit_saturating(eps, s_dev, correct_autocorrelation=True)
    if fit.usable:
        print(f"s_dev fit: x0 = {demtk.format_paren(fit.x0, fit.se_x0)}, "
              f"x_max = {demtk.format_paren(fit.x_max, fit.se_x_max)}, "
              f"beta = {demtk.format_paren(fit.beta, fit.se_beta)}, R^2 = {fit.r_squared:.4f}")
    else:
        print(f"s_dev fit not usable: {fit.not_usable_because}")
    for w in fit.warnings:
        print(f"  fit warning: {w}")
    blocks = [s_dev[(eps >= a) & (eps < a + 0.04)].mean() for a in np.arange(0.05, 0.25 - 1e-9, 0.04)]
    se = np.std(blocks, ddof=1) / np.sqrt(len(blocks))
    print(f"s_dev over eps_d = 0.05-0.25: {demtk.format_paren(np.mean(blocks), se)} "
          f"(mean of {len(blocks)} strain blocks, standard error between them; model-free)")
    np.savez(os.path.join(args.out, "networks.npz"),
             **{f"{k}_{name}": v for k, c in networks.items() for name, v in c.items()})
    try:
        import pandas as pd
        pd.DataFrame(rows).to_csv(os.path.join(args.out, "D2.csv"), index=False)
    except ImportError:
        pass
    print(f"wrote {args.out}/networks.npz ({', '.join(networks)}), D2.csv, relaxed.ckpt")


if __name__ == "__main__":
    main()
