#!/usr/bin/python3
"""Fit the compaction models of Cardenas-Barrantes et al. to curve.csv files
written by build/bin/compact.

Models (see scripts/compaction_models.py for equations and caveats):
  platzer   Eq. (Eq:Platzer)/(eq:PlatzerModified2), P* = 0, phi* = phi0: free P0, phimax
  secondi   Eq. (Eq:Secondi): free A1, n, phimax
  zhang     Eq. (Eq:Zhang):   free M, m, phimax
  Z-law     Eq. (Eq_Z_Phi):   Z - Z0 = xi (phi - phi0)^alpha: free xi, alpha (+ Z0 unless --Z0)
  paper     Eq. (eq:model):   free phimax only (b = --b, Z0/xi/alpha from the Z-law fit
            of the same curve unless --xi/--alpha/--Z0 given); --fit-b frees b too
  mixture   Eq. (Eq_toy_model_max), only with --kappa (one per file): phi1max fitted to the
            platzer and paper phimax(kappa)

Compaction fits are phi as a function of P/E (residuals and RMS in phi); the Z-law
fit has residuals in Z.  Standard errors are 1 sigma from the curve_fit covariance.

phi0: --phi0 if given (one value, or one per file); otherwise recovered exactly
from the first row of curve.csv (compact computes the first K_over_E from the
initial jammed packing at P = 0: phi0 = phi1 (K1 - P1/2)/(K1 + P1/2)); if that
fails, the lowest-pressure phi is used (with a warning).

Usage:
  /usr/bin/python3 scripts/fit_compaction.py out_k02/curve.csv out_k05/curve.csv \
      --labels "kappa=0.2" "kappa=0.5" --kappa 0.2 0.5 --out fits/compaction
  -> prints a table, writes fits/compaction.csv and fits/compaction.png
"""
import argparse
import csv
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import compaction_models as cm  # noqa: E402

COMPACTION_MODELS = ("platzer", "secondi", "zhang", "paper")


def read_curve(path):
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise ValueError(f"{path}: no data rows")
    cols = {}
    for k in rows[0]:
        try:
            cols[k] = np.array([float(r[k]) for r in rows])
        except (TypeError, ValueError):
            pass
    for need in ("P_over_E", "phi"):
        if need not in cols:
            raise ValueError(f"{path}: missing column {need}")
    order = np.argsort(cols["P_over_E"], kind="stable")
    return {k: v[order] for k, v in cols.items()}


def per_file(values, n, name):
    if values is None:
        return [None] * n
    if len(values) == 1:
        return list(values) * n
    if len(values) != n:
        sys.exit(f"fit_compaction: --{name} needs one value or one per file ({n})")
    return list(values)


def choose_phi0(d, override):
    if override is not None:
        return float(override), "given"
    P, phi = d["P_over_E"], d["phi"]
    if "K_over_E" in d:
        v = cm.infer_phi0(P[0], phi[0], d["K_over_E"][0])
        if v is not None and 0 < v <= phi[0]:
            return float(v), "from first-row K"
    print("  warning: phi0 not recoverable from K_over_E; using the lowest-pressure phi", file=sys.stderr)
    return float(phi[0]), "lowest-P phi"


def fmt(v, e):
    if e is None or not np.isfinite(e):
        return f"{v:.6g}"
    return f"{v:.6g} ± {e:.2g}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("curves", nargs="+", help="curve.csv files from build/bin/compact")
    ap.add_argument("--labels", nargs="+", help="one label per file (default: parent directory name)")
    ap.add_argument("--phi0", type=float, nargs="+", help="jammed packing fraction (one, or one per file)")
    ap.add_argument("--Z0", type=float, nargs="+", help="jammed coordination (one, or one per file); default: fitted")
    ap.add_argument("--z-column", default="Z_no_rattlers", help="coordination column (default Z_no_rattlers; or Z)")
    ap.add_argument("--b", type=float, default=0.14, help="single-particle constant b of eq:evol_1P (paper 0.14)")
    ap.add_argument("--fit-b", action="store_true", help="fit b together with phimax in the paper's model")
    ap.add_argument("--xi", type=float, help="fix xi in the paper's model (default: from the Z-law fit)")
    ap.add_argument("--alpha", type=float, help="fix alpha in the Z-law and paper model (default: fitted)")
    ap.add_argument("--kappa", type=float, nargs="+", help="mixture ratio of each file (enables the mixing-rule fit)")
    ap.add_argument("--pmin", type=float, default=0.0, help="ignore levels with P/E < pmin")
    ap.add_argument("--pmax", type=float, default=math.inf, help="ignore levels with P/E > pmax")
    ap.add_argument("--phimax-max", type=float, default=1.0, help="upper bound on fitted phimax (default 1)")
    ap.add_argument("--out", help="output prefix for .csv and .png (default: <dir of first file>/compaction_fit)")
    ap.add_argument("--no-plot", action="store_true", help="do not write the PNG")
    args = ap.parse_args(argv)

    n = len(args.curves)
    labels = args.labels or [os.path.basename(os.path.dirname(os.path.abspath(p))) or p for p in args.curves]
    if len(labels) != n:
        sys.exit("fit_compaction: --labels needs one label per file")
    phi0s = per_file(args.phi0, n, "phi0")
    Z0s = per_file(args.Z0, n, "Z0")
    kappas = per_file(args.kappa, n, "kappa") if args.kappa else None
    out = args.out or os.path.join(os.path.dirname(os.path.abspath(args.curves[0])), "compaction_fit")
    if os.path.dirname(out):
        os.makedirs(os.path.dirname(out), exist_ok=True)

    rows = []       # (label, file, model, param, value, stderr, fixed, rms, residual, nobs)
    datasets = []
    for path, label, phi0_o, Z0_o in zip(args.curves, labels, phi0s, Z0s):
        d = read_curve(path)
        sel = (d["P_over_E"] >= args.pmin) & (d["P_over_E"] <= args.pmax) & (d["P_over_E"] > 0)
        phi0, how = choose_phi0(d, phi0_o)
        P, phi = d["P_over_E"][sel], d["phi"][sel]
        print(f"\n{label}: {path}  ({sel.sum()} levels, P/E {P.min():.3g}..{P.max():.3g}, "
              f"phi {phi.min():.5f}..{phi.max():.5f}; phi0 = {phi0:.6f} [{how}])")
        fits = {}

        def record(name, fn):
            try:
                r = fn()
            except Exception as e:  # noqa: BLE001
                print(f"  {name:8s} fit failed: {e}")
                return None
            fits[name] = r
            for pn, v, e in zip(r.names, r.values, r.stderr):
                rows.append((label, path, name, pn, v, e, 0, r.rms, r.residual, r.nobs))
            for pn, v in r.fixed.items():
                rows.append((label, path, name, pn, v, float("nan"), 1, r.rms, r.residual, r.nobs))
            return r

        record("platzer", lambda: cm.fit_platzer(P, phi, phi0, phimax_hi=args.phimax_max))
        record("secondi", lambda: cm.fit_secondi(P, phi, phi0, phimax_hi=args.phimax_max))
        record("zhang", lambda: cm.fit_zhang(P, phi, phi0, phimax_hi=args.phimax_max))
        zr = None
        if args.z_column in d:
            Z = d[args.z_column][sel]
            zr = record("Z-law", lambda: cm.fit_coordination(phi, Z, phi0, Z0=Z0_o, alpha=args.alpha))
        else:
            print(f"  no column {args.z_column}: Z-law skipped")
        Z0p = Z0_o if Z0_o is not None else (zr["Z0"] if zr else None)
        xip = args.xi if args.xi is not None else (zr["xi"] if zr else None)
        alp = args.alpha if args.alpha is not None else (zr["alpha"] if zr else None)
        if None in (Z0p, xip, alp):
            print("  paper    skipped: needs Z0, xi, alpha (Z-law fit or --Z0/--xi/--alpha)")
        else:
            record("paper", lambda: cm.fit_paper_model(P, phi, phi0, Z0p, xip, alp, b=args.b, fit_b=args.fit_b,
                                                       phimax_hi=args.phimax_max))
        datasets.append(dict(label=label, d=d, sel=sel, phi0=phi0, fits=fits))

    # mixing rule across files
    mix = {}
    if kappas is not None:
        phi0_mix = float(np.mean([ds["phi0"] for ds in datasets]))
        for model in ("platzer", "paper"):
            pairs = [(k, ds["fits"][model]["phimax"]) for k, ds in zip(kappas, datasets) if model in ds["fits"]]
            if len(pairs) >= 1:
                try:
                    k, pm = map(np.array, zip(*pairs))
                    r = cm.fit_phimax_mixture(k, pm, phi0_mix)
                except Exception as e:  # noqa: BLE001
                    print(f"mixing rule ({model}) failed: {e}")
                    continue
                mix[model] = (k, pm, r)
                rows.append(("all", ";".join(args.curves), f"mixture[{model}]", "phi1max", r["phi1max"],
                             r.err("phi1max"), 0, r.rms, r.residual, r.nobs))
                rows.append(("all", ";".join(args.curves), f"mixture[{model}]", "phi0", phi0_mix, float("nan"), 1,
                             r.rms, r.residual, r.nobs))

    # table
    print("\n%-18s %-14s %-52s %-10s %s" % ("curve", "model", "fitted parameters (± 1 sigma)", "rms", "fixed"))
    print("-" * 120)
    for ds in datasets:
        for name, r in ds["fits"].items():
            par = ", ".join(f"{pn}={fmt(v, e)}" for pn, v, e in zip(r.names, r.values, r.stderr))
            fx = ", ".join(f"{k}={v:.5g}" for k, v in r.fixed.items())
            print("%-18s %-14s %-52s %-10s %s" % (ds["label"][:18], name, par, f"{r.rms:.2e} ({r.residual})", fx))
    for model, (_, _, r) in mix.items():
        print("%-18s %-14s %-52s %-10s %s" % ("all", f"mixture[{model}]", f"phi1max={fmt(r['phi1max'], r.err('phi1max'))}",
                                               f"{r.rms:.2e} (phimax)", f"phi0={r['phi0']:.5g}"))

    with open(out + ".csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["label", "file", "model", "parameter", "value", "stderr", "fixed", "rms", "residual_in", "n_points"])
        for row in rows:
            w.writerow([row[0], row[1], row[2], row[3], f"{row[4]:.10g}", f"{row[5]:.4g}", row[6], f"{row[7]:.4g}",
                        row[8], row[9]])
    print(f"\nwrote {out}.csv")
    if not args.no_plot:
        plot(datasets, mix, args, out + ".png")
        print(f"wrote {out}.png")
    return 0


STYLE = {"platzer": ("--", "Platzer (eq. Platzer)"), "secondi": (":", "Secondi"), "zhang": ("-.", "Zhang"),
         "paper": ("-", "paper eq:model")}


def plot(datasets, mix, args, png):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ncol = 4 if mix else 3
    fig, ax = plt.subplots(1, ncol, figsize=(5.2 * ncol, 4.6))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, ds in enumerate(datasets):
        c = colors[i % len(colors)]
        d, sel, phi0, fits = ds["d"], ds["sel"], ds["phi0"], ds["fits"]
        P, phi = d["P_over_E"][sel], d["phi"][sel]
        # (a) phi vs P/E, lin-log as the paper's Fig. phi_p
        ax[0].semilogx(P, phi, "o", color=c, ms=4, mfc="none", label=ds["label"])
        Pg = np.geomspace(P.min(), P.max(), 200)
        for name in COMPACTION_MODELS:
            if name in fits:
                ax[0].semilogx(Pg, fits[name].predict(Pg), STYLE[name][0], color=c, lw=1,
                               label=STYLE[name][1] if i == 0 else None)
        # (b) Z - Z0 vs phi - phi0, log-log
        if "Z-law" in fits and args.z_column in d:
            zr = fits["Z-law"]
            Z0 = zr["Z0"]
            dphi, dZ = phi - phi0, d[args.z_column][sel] - Z0
            ok = (dphi > 0) & (dZ > 0)
            ax[1].loglog(dphi[ok], dZ[ok], "o", color=c, ms=4, mfc="none", label=f"{ds['label']} (Z0={Z0:.3g})")
            if ok.any():
                xg = np.geomspace(dphi[ok].min(), dphi[ok].max(), 100)
                ax[1].loglog(xg, zr["xi"] * xg ** zr["alpha"], "-", color=c, lw=1)
        # (c) K/E vs phi
        if "K_over_E" in d:
            K = d["K_over_E"][sel]
            ok = np.isfinite(K) & (K > 0)
            # compact's K is between levels: plot it at the mid packing fraction
            phim = 0.5 * (phi + np.concatenate([[phi0], phi[:-1]]))
            ax[2].semilogy(phim[ok], K[ok], "o", color=c, ms=4, mfc="none", label=ds["label"])
        phig = np.linspace(phi0 + 1e-4 * (phi.max() - phi0), phi.max(), 200)
        for name in COMPACTION_MODELS:
            if name in fits and fits[name].K is not None:
                Kg = np.where(phig < fits[name]["phimax"], fits[name].K(np.minimum(phig, fits[name]["phimax"] - 1e-12)),
                              np.nan)
                ax[2].semilogy(phig, Kg, STYLE[name][0], color=c, lw=1)
        if "Z-law" in fits and "paper" in fits:
            pr = fits["paper"].params
            pg = phig[phig < pr["phimax"]]
            ax[2].semilogy(pg, cm.paper_model_K_exact(pg, pr["phimax"], pr["b"], pr["Z0"], pr["xi"], pr["alpha"],
                                                        phi0), ls=(0, (1, 3)), color=c, lw=1.5,
                           label="exact d/dphi of eq:model" if i == 0 else None)
        if args.z_column in d and "Z-law" in fits:
            Kv = cm.voigt_K1(phi, d[args.z_column][sel], fits["Z-law"]["Z0"], phi0)
            ax[2].semilogy(phi, np.where(Kv > 0, Kv, np.nan), "x", color=c, ms=4,
                           label="K1 Voigt (data Z)" if i == 0 else None)
    ax[0].set(xlabel="P/E", ylabel=r"$\phi$", title=r"$\phi$ vs P/E (lines: fits)")
    ax[1].set(xlabel=r"$\phi-\phi_0$", ylabel=r"$Z-Z_0$ (" + args.z_column + ")",
              title=r"$Z-Z_0=\xi(\phi-\phi_0)^\alpha$")
    ax[2].set(xlabel=r"$\phi$", ylabel="K/E", title=r"K = $\phi\,dP/d\phi$ (paper: K2 for eq:model)")
    if mix:
        for model, (k, pm, r) in mix.items():
            mk = "s" if model == "platzer" else "o"
            ax[3].plot(k, pm, mk, mfc="none" if model == "platzer" else None, label=f"{model} phimax")
            kg = np.linspace(0, 1, 100)
            ax[3].plot(kg, r.predict(kg), "--", lw=1, label=f"Eq_toy_model_max, phi1max={r['phi1max']:.4f}")
        ax[3].set(xlabel=r"$\kappa$", ylabel=r"$\phi_{max}$", title="mixing rule")
    for a in ax:
        a.grid(alpha=0.3, which="both")
        a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(png, dpi=130)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
