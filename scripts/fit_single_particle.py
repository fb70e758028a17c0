#!/usr/bin/python3
"""Fit the paper's single-particle compaction law to one or more curve.csv files.

    P_p/E = -b ln((phi_max - phi_p) / (phi_max - phi_0)),   phi_0 = pi/4 (fixed)

Fitted parameters: b and phi_max (scipy.optimize.curve_fit), with standard errors
from the covariance matrix, and the RMS residual.

Which variable is fitted: phi_p as a function of P/E, i.e. the inverted law
    phi_p(P) = phi_max - (phi_max - phi_0) exp(-(P/E) / b).
Reason: P/E is the imposed control variable (exact, the walls are pressure-driven),
while phi_p is the computed response that carries the discretisation/solver error.
The inverted form is also smooth for every (b, phi_max), whereas P(phi) has a log
singularity at phi = phi_max (undefined when an iterate has phi_max <= max phi_p)
and gives the highest-pressure points unbounded leverage.  The P(phi) fit
(residuals in P/E) is reported too, with --both, for comparison.

Usage:
  /usr/bin/python3 scripts/fit_single_particle.py run92/curve.csv run3872/curve.csv \
      --labels "92 tri" "3872 tri" --png benchmarks/single_particle_fit.png
Options: --pmin/--pmax restrict the fitted P/E range; --phi0 overrides pi/4.
"""
import argparse
import csv
import math
import os
import sys

import numpy as np
from scipy.optimize import curve_fit

PHI0 = math.pi / 4


def read_curve(path):
    rows = list(csv.DictReader(open(path)))
    P = np.array([float(r["P_over_E"]) for r in rows])
    phi = np.array([float(r["phi"]) for r in rows])
    return P, phi


def fit_phi_of_P(P, phi, phi0):
    def model(p, b, phimax):
        return phimax - (phimax - phi0) * np.exp(-p / b)
    p0 = (0.14, max(phi.max() + 0.01, 0.95))
    popt, pcov = curve_fit(model, P, phi, p0=p0, maxfev=20000)
    res = phi - model(P, *popt)
    return popt, np.sqrt(np.diag(pcov)), float(np.sqrt(np.mean(res ** 2))), model


def fit_P_of_phi(P, phi, phi0, start):
    # phi_max is parametrised as max(phi) + exp(s) so the log stays defined
    top = phi.max()

    def model(ph, b, s):
        pm = top + np.exp(s)
        return -b * np.log((pm - ph) / (pm - phi0))
    s0 = math.log(max(start[1] - top, 1e-4))
    popt, pcov = curve_fit(model, phi, P, p0=(start[0], s0), maxfev=20000)
    b, s = popt
    pm = top + math.exp(s)
    se = np.sqrt(np.diag(pcov))
    res = P - model(phi, *popt)
    return (b, pm), (se[0], math.exp(s) * se[1]), float(np.sqrt(np.mean(res ** 2)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("curves", nargs="+", help="curve.csv files written by build/bin/single-particle")
    ap.add_argument("--labels", nargs="*", help="legend labels (default: parent directory names)")
    ap.add_argument("--png", default="single_particle_fit.png")
    ap.add_argument("--pmin", type=float, default=0.0)
    ap.add_argument("--pmax", type=float, default=np.inf)
    ap.add_argument("--phi0", type=float, default=PHI0, help="phi_{p,0} (default pi/4)")
    ap.add_argument("--both", action="store_true", help="also fit P(phi) (residuals in P/E)")
    ap.add_argument("--paper-b", type=float, default=0.14, help="draw the paper's b with the first fit's phi_max")
    a = ap.parse_args()
    labels = a.labels if a.labels else [os.path.basename(os.path.dirname(os.path.abspath(c))) for c in a.curves]
    if len(labels) != len(a.curves):
        sys.exit("need one label per curve")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5.6, 4.4), dpi=100)
    print(f"fit of phi_p(P/E) = phi_max - (phi_max - phi0) exp(-(P/E)/b), phi0 = {a.phi0:.6f}, "
          f"P/E in [{a.pmin}, {a.pmax}]")
    print(f"{'curve':>14} {'n':>3} {'b':>9} {'+-':>8} {'phi_max':>9} {'+-':>8} {'rms(phi)':>9}"
          + ("   | P(phi) fit: b, phi_max, rms(P/E)" if a.both else ""))
    both_fits = []
    first = None
    for k, (path, lab) in enumerate(zip(a.curves, labels)):
        P, phi = read_curve(path)
        m = (P >= a.pmin) & (P <= a.pmax)
        (b, pm), (sb, spm), rms, model = fit_phi_of_P(P[m], phi[m], a.phi0)
        if first is None:
            first = (b, pm)
        line = f"{lab:>14} {m.sum():3d} {b:9.5f} {sb:8.5f} {pm:9.5f} {spm:8.5f} {rms:9.2e}"
        if a.both:
            (b2, pm2), (sb2, spm2), rms2 = fit_P_of_phi(P[m], phi[m], a.phi0, (b, pm))
            rms2phi = float(np.sqrt(np.mean((phi[m] - model(P[m], b2, pm2)) ** 2)))
            line += f"   | {b2:.5f}+-{sb2:.5f}, {pm2:.5f}+-{spm2:.5f}, {rms2:.2e} (rms(phi) {rms2phi:.2e})"
        print(line)
        c = f"C{k}"
        ax.plot(phi, P, "o" if k == 0 else "s^vD<>"[k % 7 - 1], color=c, mfc="none", ms=5,
                label=f"{lab} (data)")
        ph = np.linspace(a.phi0, min(pm - 1e-5, phi.max() + 0.002), 300)
        ax.plot(ph, -b * np.log((pm - ph) / (pm - a.phi0)), "-", color=c, lw=1,
                label=rf"fit $\phi(P)$: b={b:.3f}, $\phi_{{max}}$={pm:.4f}")
        if a.both:
            ph2 = np.linspace(a.phi0, pm2 - 1e-5, 300)
            ax.plot(ph2, -b2 * np.log((pm2 - ph2) / (pm2 - a.phi0)), ":", color=c, lw=1.2,
                    label=rf"fit $P(\phi)$: b={b2:.3f}, $\phi_{{max}}$={pm2:.4f}")
    if a.paper_b and first is not None:
        pm = first[1]
        ph = np.linspace(a.phi0, pm - 1e-5, 300)
        ax.plot(ph, -a.paper_b * np.log((pm - ph) / (pm - a.phi0)), "--", color="gray", lw=1,
                label=f"b={a.paper_b} (paper), same $\\phi_{{max}}$")
    ax.set_xlabel(r"$\phi_p$")
    ax.set_ylabel(r"$P_p/E$")
    ax.set_ylim(0, 0.6)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title(r"single particle: $P_p/E=-b\ln[(\phi_{max}-\phi_p)/(\phi_{max}-\pi/4)]$", fontsize=9)
    fig.tight_layout()
    fig.savefig(a.png)
    print(f"wrote {a.png}")


if __name__ == "__main__":
    main()
