"""Luding's elasto-plastic adhesive contact law in closed form (S. Luding, Granular Matter 10
(2008) 235-246, sec. 2.1, with the elastic limit branch beyond delta* that MercuryDPM's
LinearPlasticViscoelastic species and YADE's Law2_ScGeom_LudingPhys_Basic share), written from
the law's definition for the figures and tests: it does not call the C++ law
(sim/include/dem/contact/normal_luding.hpp).

Units: stiffnesses N/m, overlaps m, forces N, a12 = r_i r_j/(r_i + r_j) m, masses kg, speeds m/s.
"""
import math
from dataclasses import dataclass


@dataclass
class Luding:
    k1: float            # loading stiffness [N/m]
    kp: float            # un-/reloading limit stiffness [N/m], > k1
    kc: float            # adhesive stiffness [N/m], >= 0
    phi_f: float         # plasticity depth [-]
    a12: float           # pair radius r_i r_j/(r_i + r_j) [m]

    @property
    def delta0_limit(self):
        """The largest plastic overlap phi_f 2 a12 [m]."""
        return self.phi_f * 2 * self.a12

    @property
    def delta_star(self):
        """The overlap beyond which the contact is elastic along kp [m]."""
        return self.kp / (self.kp - self.k1) * self.delta0_limit

    def k2(self, dmax):
        return self.kp if dmax >= self.delta_star else self.k1 + (self.kp - self.k1) * dmax / self.delta_star

    def delta0(self, dmax):
        return (1 - self.k1 / self.k2(dmax)) * dmax

    def adhesive_delta_max(self, d):
        """The delta_max whose own k2-line passes through (d, -kc d): solves
        k2(h) d - (k2(h) - k1) h = -kc d for h (k2 linear in h below delta*, kp beyond)."""
        c = (self.kp - self.k1) / self.delta_star
        h = 0.5 * d + math.sqrt(0.25 * d * d + (self.k1 + self.kc) * d / c)
        return h if h < self.delta_star else (self.kp + self.kc) / (self.kp - self.k1) * d

    def path(self, deltas):
        """Forces [N] along a sequence of overlaps (>= 0), and delta_max after each: the branch
        logic of the law (virgin k1 up to delta*, the kp limit branch beyond, the k2-line in
        between, the adhesive limit -kc delta moving delta_max down so that the k2-line of the
        new delta_max passes through the point)."""
        dmax, out = 0.0, []
        for d in deltas:
            k2 = self.k2(dmax)
            f = k2 * (d - self.delta0(dmax))
            if f >= self.k1 * d:                         # on or beyond the virgin branch
                if d < self.delta_star:
                    dmax, f = max(dmax, d), self.k1 * d
                else:
                    dmax = self.delta_star
                    f = self.kp * (d - self.delta0_limit)
            elif f <= -self.kc * d:                      # the adhesive limit
                dmax, f = self.adhesive_delta_max(d), -self.kc * d
            out.append((f, dmax))
        return out

    def delta_max_of_impact(self, m_r, v):
        """The largest overlap of a head-on impact at relative speed v [m/s] (no dashpot)."""
        e_in, ds, d0s = 0.5 * m_r * v * v, self.delta_star, self.delta0_limit
        if e_in <= 0.5 * self.k1 * ds * ds:
            return math.sqrt(2 * e_in / self.k1)
        return d0s + math.sqrt((ds - d0s) ** 2 + (2 * e_in - self.k1 * ds * ds) / self.kp)

    def restitution(self, m_r, v):
        """e = sqrt(energy out / energy in) of a head-on impact without dashpot: out is the work
        of unloading along k2 (delta - delta0) down to the adhesive limit at
        delta_c = k2 delta0/(k2 + kc), then along -kc delta to separation; 0 when that work is
        negative (the adhesive well holds the pair: sticking)."""
        dm = self.delta_max_of_impact(m_r, v)
        k2, d0 = self.k2(dm), (self.delta0_limit if dm >= self.delta_star else self.delta0(dm))
        dc = k2 * d0 / (k2 + self.kc)
        out = 0.5 * k2 * ((dm - d0) ** 2 - (dc - d0) ** 2) - 0.5 * self.kc * dc * dc
        return math.sqrt(out / (0.5 * m_r * v * v)) if out > 0 else 0.0

    def sticking_window(self, m_r, v_lo=1e-3, v_hi=1e3, n=4000):
        """(v_first, v_last) [m/s] of impact speeds that stick on a log grid, or None."""
        vs = [v_lo * (v_hi / v_lo) ** (k / (n - 1)) for k in range(n)]
        stuck = [v for v in vs if self.restitution(m_r, v) == 0.0]
        return (stuck[0], stuck[-1]) if stuck else None
