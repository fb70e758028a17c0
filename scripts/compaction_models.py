"""Compaction, connectivity and bulk-modulus models of Cardenas-Barrantes et al.,
"Compaction of mixtures of rigid and highly deformable particles"
(reference: /work/shared/reference/compaction-rigid-deformable-mixtures.tex).

Conventions used throughout
---------------------------
* Pressures and moduli are reduced by the Young modulus E: ``P`` means P/E and
  ``K`` means K/E.  Model pressure parameters (A1, M, P0, P*) are therefore in
  units of E as well (for Secondi with n != 1, A1 is in units of E**n).
* phi is the packing (area) fraction, phi0 the jammed packing fraction of the
  rigid assembly (P/E -> 0), phimax the asymptotic packing fraction P/E -> inf.
* Bulk modulus, Eq. (Eq_Modulus):  K = dP/dphi * dphi/deps_v with
  eps_v = -ln(phi0/phi) = ln(phi/phi0), so dphi/deps_v = phi and K = phi dP/dphi.
* Each compaction model is given as P(phi) (the paper's form), as the inverse
  phi(P) (closed form where one exists), and with its analytic K(phi).
* Fits are done on phi as a function of P/E (P/E is the imposed control
  variable, phi the measured response; the inverse forms are smooth for every
  parameter value, whereas P(phi) is singular at phi = phimax).  Residuals and
  RMS are therefore in phi.

Only numpy and scipy are used.
"""
import math

import numpy as np
from scipy.optimize import brentq, curve_fit

__all__ = [
    "secondi_P", "secondi_phi", "secondi_K",
    "zhang_P", "zhang_phi", "zhang_K",
    "platzer_P", "platzer_phi", "platzer_K", "platzer_original_void_ratio",
    "single_particle_P", "single_particle_phi", "single_particle_K",
    "coordination_Z", "xi_from_max",
    "paper_model_P", "paper_model_phi", "paper_model_K_exact", "paper_K2",
    "voigt_K1", "phimax_mixture",
    "bulk_modulus_fd", "bulk_modulus_midpoint", "infer_phi0",
    "FitResult", "fit_platzer", "fit_secondi", "fit_zhang", "fit_coordination",
    "fit_paper_model", "fit_single_particle", "fit_phimax_mixture",
]

TWO_PI = 2.0 * math.pi
_TINY = 1e-300


def _ratio(phi, phimax, phiref):
    """(phimax - phi) / (phimax - phiref), clipped to stay > 0 (used inside logs)."""
    phi = np.asarray(phi, dtype=float)
    return np.maximum((phimax - phi) / (phimax - phiref), _TINY)


# --------------------------------------------------------------------------
# Secondi, Eq. (Eq:Secondi)
# --------------------------------------------------------------------------
def secondi_P(phi, A1, n, phimax, phi0):
    """Secondi (2002), paper Eq. (Eq:Secondi):

        P**n = -A1 ln[(phimax - phi) / (phimax - phi0)]

    i.e. P = (-A1 ln[...])**(1/n).  n = phimax = 1 gives Heckel; n = 1 gives
    Heuberger/Ballhausen; phimax = 1 gives Parilak; n = 0.5, phimax = 1 Panelli.
    Reduced units: P = P/E and A1 = A1/E**n (the paper quotes A1 ~ 0.05 E for
    kappa = 1, mu = 0, with n = 1)."""
    L = -np.log(_ratio(phi, phimax, phi0))
    return np.power(np.maximum(A1 * L, 0.0), 1.0 / n)


def secondi_phi(P, A1, n, phimax, phi0):
    """Inverse of Eq. (Eq:Secondi): phi = phimax - (phimax - phi0) exp(-P**n / A1)."""
    P = np.asarray(P, dtype=float)
    return phimax - (phimax - phi0) * np.exp(-np.power(np.maximum(P, 0.0), n) / A1)


def secondi_K(phi, A1, n, phimax, phi0):
    """K = phi dP/dphi for Eq. (Eq:Secondi):
    K = phi/(n (phimax - phi)) * A1**(1/n) * L**(1/n - 1), L = -ln[(phimax-phi)/(phimax-phi0)].
    (Diverges at phi0 for n > 1, vanishes there for n < 1.)"""
    phi = np.asarray(phi, dtype=float)
    L = np.maximum(-np.log(_ratio(phi, phimax, phi0)), _TINY)
    return phi / (n * (phimax - phi)) * A1 ** (1.0 / n) * np.power(L, 1.0 / n - 1.0)


# --------------------------------------------------------------------------
# Zhang et al., Eq. (Eq:Zhang)
# --------------------------------------------------------------------------
def _zhang_L(phi, phimax, phi0):
    phi = np.asarray(phi, dtype=float)
    arg = (phimax - phi0) * phi / (np.maximum(phimax - phi, _TINY) * phi0)
    return np.log(np.maximum(arg, _TINY))


def zhang_P(phi, M, m, phimax, phi0):
    """Zhang et al. (2014), paper Eq. (Eq:Zhang):

        log P = m log ln[ (phimax - phi0) phi / ((phimax - phi) phi0) ] + log M

    i.e. P = M * (ln[(phimax - phi0) phi / ((phimax - phi) phi0)])**m.  The base
    of the outer 'log' cancels.  Reduced units: P = P/E, M = M/E (paper:
    m = 1, M ~ A1 ~ 0.05 E for kappa = 1, mu = 0)."""
    return M * np.power(np.maximum(_zhang_L(phi, phimax, phi0), 0.0), m)


def zhang_phi(P, M, m, phimax, phi0):
    """Inverse of Eq. (Eq:Zhang): with r = exp((P/M)**(1/m)),
    phi = r phimax phi0 / (phimax - phi0 + r phi0)."""
    P = np.asarray(P, dtype=float)
    x = np.power(np.maximum(P, 0.0) / M, 1.0 / m)
    # divide numerator and denominator by r to avoid overflow: phi = phimax phi0 / ((phimax-phi0)/r + phi0)
    return phimax * phi0 / ((phimax - phi0) * np.exp(-x) + phi0)


def zhang_K(phi, M, m, phimax, phi0):
    """K = phi dP/dphi for Eq. (Eq:Zhang): K = M m L**(m-1) phimax / (phimax - phi),
    L = ln[(phimax-phi0) phi / ((phimax-phi) phi0)]."""
    phi = np.asarray(phi, dtype=float)
    L = np.maximum(_zhang_L(phi, phimax, phi0), _TINY)
    return M * m * np.power(L, m - 1.0) * phimax / (phimax - phi)


# --------------------------------------------------------------------------
# Platzer et al., Eq. (Eq:Platzer) / appendix Eqs. (eq:PlatzerOriginal),
# (eq:PlatzerModified2)
# --------------------------------------------------------------------------
def platzer_P(phi, P0, phimax, phistar, Pstar=0.0):
    """Simplified Platzer et al. (2018) model, appendix Eq. (eq:PlatzerModified2):

        P = -P0 ln[(phimax - phi) / (phimax - phistar)] + Pstar

    AMBIGUITY: the main-text Eq. (Eq:Platzer) is printed WITHOUT the leading
    minus sign, which would give P < P* for phi > phi* (unphysical with P0 > 0).
    The appendix form (with the minus) is used here; it is also what follows from
    the original void-ratio form (see platzer_original_void_ratio).
    The paper imposes Pstar = 0 and phistar = phi0; the model is then identical to
    Secondi with n = 1, A1 = P0.  NOTE: Pstar and phistar are not separately
    identifiable from a curve -- they only enter through the constant
    Pstar + P0 ln(phimax - phistar)."""
    return -P0 * np.log(_ratio(phi, phimax, phistar)) + Pstar


def platzer_phi(P, P0, phimax, phistar, Pstar=0.0):
    """Inverse of Eq. (eq:PlatzerModified2): phi = phimax - (phimax - phistar) exp(-(P - Pstar)/P0)."""
    P = np.asarray(P, dtype=float)
    return phimax - (phimax - phistar) * np.exp(-(P - Pstar) / P0)


def platzer_K(phi, P0, phimax, phistar=None, Pstar=0.0):
    """K = phi dP/dphi for Eq. (eq:PlatzerModified2): K = P0 phi / (phimax - phi)
    (independent of phistar and Pstar)."""
    phi = np.asarray(phi, dtype=float)
    return P0 * phi / (phimax - phi)


def platzer_original_void_ratio(P, kappa, e_sand, fstar, F, P0, Pstar):
    """Original Platzer et al. form, appendix Eq. (eq:PlatzerOriginal), void fraction e = 1 - phi:

        e(kappa, P) = e(0, P) - kappa f* - kappa (F - f*) [1 - exp((P* - P)/P0)]

    e_sand = e(0, P) (a number or an array matching P).  For rigid 'sand'
    (e(0,P) = 1 - phi0 constant) this is exactly eq:PlatzerModified2 with
    phistar = phi0 + kappa f*, phimax = phi0 + kappa F."""
    P = np.asarray(P, dtype=float)
    return e_sand - kappa * fstar - kappa * (F - fstar) * (1.0 - np.exp((Pstar - P) / P0))


# --------------------------------------------------------------------------
# Single particle, Eq. (eq:evol_1P)
# --------------------------------------------------------------------------
def single_particle_P(phi, b, phimax, phi0=math.pi / 4):
    """Single particle in a box, paper Eq. (eq:evol_1P):
        P_p/E = -b ln[(phi_p,max - phi_p) / (phi_p,max - phi_p,0)],  phi_p,0 = pi/4, b ~ 0.14."""
    return -b * np.log(_ratio(phi, phimax, phi0))


def single_particle_phi(P, b, phimax, phi0=math.pi / 4):
    """Inverse of Eq. (eq:evol_1P): phi_p = phimax - (phimax - phi0) exp(-P/b)."""
    return phimax - (phimax - phi0) * np.exp(-np.asarray(P, dtype=float) / b)


def single_particle_K(phi, b, phimax, phi0=math.pi / 4):
    """K_p/E = phi_p dP_p/dphi_p = b phi_p / (phimax - phi_p)  (eps_v,p = -ln(phi_p,0/phi_p))."""
    phi = np.asarray(phi, dtype=float)
    return b * phi / (phimax - phi)


# --------------------------------------------------------------------------
# Connectivity, Eq. (Eq_Z_Phi)
# --------------------------------------------------------------------------
def coordination_Z(phi, Z0, xi, alpha, phi0):
    """Paper Eq. (Eq_Z_Phi):  Z - Z0 = xi (phi - phi0)**alpha   (paper: alpha ~ 0.5, xi ~ 5.1).
    Returns Z; (phi - phi0) is clipped at 0 below the jammed state."""
    d = np.maximum(np.asarray(phi, dtype=float) - phi0, 0.0)
    return Z0 + xi * np.power(d, alpha)


def xi_from_max(Zmax, Z0, phimax, phi0, alpha):
    """xi = (Zmax - Z0) / (phimax - phi0)**alpha (text below Eq. Eq_Z_Phi)."""
    return (Zmax - Z0) / (phimax - phi0) ** alpha


# --------------------------------------------------------------------------
# The paper's compaction and bulk equations, Eqs. (eq:model), (eq:K_predict)
# --------------------------------------------------------------------------
def paper_model_P(phi, phimax, b, Z0, xi, alpha, phi0):
    """The paper's compaction equation, Eq. (eq:model):

        P/E = -(b phi / 2 pi) {Z0 + xi (phi - phi0)**alpha} ln[(phimax - phi)/(phimax - phi0)]

    (Eq. eq:P_Pp, P = Z phi P_p / (2 pi), with Z from Eq_Z_Phi and P_p from
    eq:evol_1P evaluated at phi_p = phi).  NOTE: eq:evol_1P is written with
    phi_p,0 = pi/4 in the log while eq:model uses phi0 (the jammed fraction of
    the mixture) -- the paper substitutes phi0 without comment; we follow eq:model.
    Also eq:Pglobal_local has phi Z / pi but eq:P_Pp / eq:model use phi Z / (2 pi);
    eq:model is implemented as printed."""
    phi = np.asarray(phi, dtype=float)
    Z = coordination_Z(phi, Z0, xi, alpha, phi0)
    return -(b * phi / TWO_PI) * Z * np.log(_ratio(phi, phimax, phi0))


def paper_model_phi(P, phimax, b, Z0, xi, alpha, phi0):
    """Inverse of Eq. (eq:model) by bracketed root finding on (phi0, phimax)
    (P(phi) is strictly increasing there when b, Z0 > 0, xi >= 0)."""
    P = np.atleast_1d(np.asarray(P, dtype=float))
    out = np.empty_like(P)
    gap = phimax - phi0
    for i, p in enumerate(P):
        if p <= 0.0:
            out[i] = phi0
            continue
        lo, hi = phi0, phimax - gap * 1e-15
        f = lambda x: paper_model_P(x, phimax, b, Z0, xi, alpha, phi0) - p
        if f(hi) <= 0.0:
            out[i] = hi
        else:
            out[i] = brentq(f, lo, hi, xtol=1e-15 * max(gap, 1e-300) + 1e-15, rtol=1e-14, maxiter=200)
    return out


def paper_model_K_exact(phi, phimax, b, Z0, xi, alpha, phi0):
    """Exact K = phi dP/dphi of Eq. (eq:model):

        K/E = (b phi / 2 pi) [ phi Z / (phimax - phi) - (Z + phi xi alpha (phi-phi0)**(alpha-1)) ln r ],
        r = (phimax - phi)/(phimax - phi0), Z = Z0 + xi (phi - phi0)**alpha.

    The second group is the 'O' term the paper drops in Eq. (eq:K_predict)."""
    phi = np.asarray(phi, dtype=float)
    d = np.maximum(phi - phi0, _TINY)
    Z = Z0 + xi * d ** alpha
    dZ = xi * alpha * d ** (alpha - 1.0)
    lnr = np.log(_ratio(phi, phimax, phi0))
    return (b * phi / TWO_PI) * (phi * Z / (phimax - phi) - (Z + phi * dZ) * lnr)


def paper_K2(phi, phimax, b, Z0, xi, alpha, phi0):
    """Paper Eq. (eq:K_predict):

        K2/E = b phi**2 / (2 pi (phimax - phi)) {Z0 + xi (phi - phi0)**alpha}

    AMBIGUITY: the paper says this is obtained by 'derivating Eq. (eq:model)', but
    it is only the term from differentiating the logarithm (= Z phi/(2 pi) K_p,
    Eq. eq:K_Kp); the exact derivative adds the terms of paper_model_K_exact.
    Implemented as printed."""
    phi = np.asarray(phi, dtype=float)
    return b * phi ** 2 / (TWO_PI * (phimax - phi)) * coordination_Z(phi, Z0, xi, alpha, phi0)


def voigt_K1(phi, Z, Z0, phi0):
    """Voigt / effective-medium estimate, paper Eq. (Eq_Bulk_K1):

        K1/E = (Z phi / 2 pi) (5/2 - phi0/phi) - Z0 phi / (4 pi)

    Z is the measured (or modelled) coordination at phi.  Tends to Z phi/(2 pi)
    as phi -> phi0 with Z -> Z0."""
    phi = np.asarray(phi, dtype=float)
    return Z * phi / TWO_PI * (2.5 - phi0 / phi) - Z0 * phi / (2.0 * TWO_PI)


def phimax_mixture(kappa, phi0, phi1max):
    """Two-phase (demixed) mixing rule, paper Eq. (Eq_toy_model_max):

        phimax(kappa) = phi0 phi1max / (phi1max + (phi0 - phi1max) kappa)

    phi0 = phi(kappa = 0) (rigid jammed packing), phi1max = phimax at kappa = 1.
    (Same form as Eq. Eq_toy_model for phi(kappa).)"""
    kappa = np.asarray(kappa, dtype=float)
    return phi0 * phi1max / (phi1max + (phi0 - phi1max) * kappa)


# --------------------------------------------------------------------------
# Bulk modulus from data
# --------------------------------------------------------------------------
def bulk_modulus_fd(P, phi):
    """K = phi dP/dphi from sampled (P, phi) by second-order finite differences
    (numpy.gradient on a possibly non-uniform grid); returns K at the samples."""
    P = np.asarray(P, dtype=float)
    phi = np.asarray(phi, dtype=float)
    return phi * np.gradient(P, phi, edge_order=2)


def bulk_modulus_midpoint(P, phi, phi_start=None, P_start=0.0):
    """K between successive levels exactly as build/bin/compact writes K_over_E:
    K_i = (phi_i + phi_{i-1})/2 * (P_i - P_{i-1}) / (phi_i - phi_{i-1}),
    with (phi_{-1}, P_{-1}) = (phi_start, P_start) (compact uses the initial jammed
    packing and P = 0).  If phi_start is None the first value is NaN."""
    P = np.asarray(P, dtype=float)
    phi = np.asarray(phi, dtype=float)
    pp = np.concatenate([[P_start], P])
    ff = np.concatenate([[np.nan if phi_start is None else phi_start], phi])
    with np.errstate(divide="ignore", invalid="ignore"):
        return 0.5 * (ff[1:] + ff[:-1]) * np.diff(pp) / np.diff(ff)


def infer_phi0(P1, phi1, K1):
    """Recover the starting packing fraction phi0 from the FIRST row of a compact
    curve.csv: compact writes K1 = (phi1 + phi0)/2 * P1/(phi1 - phi0) (P from 0), so
    phi0 = phi1 (K1 - P1/2) / (K1 + P1/2).  Returns None if not usable."""
    if not (np.isfinite(K1) and np.isfinite(P1) and np.isfinite(phi1)) or K1 <= 0 or P1 <= 0:
        return None
    return phi1 * (K1 - 0.5 * P1) / (K1 + 0.5 * P1)


# --------------------------------------------------------------------------
# Fitting helpers
# --------------------------------------------------------------------------
class FitResult:
    """Result of a fit: names, values, standard errors (1 sigma, from the
    curve_fit covariance; NaN for fixed parameters or a singular covariance),
    fixed parameters, RMS residual, residual variable and the callables."""

    def __init__(self, model, names, values, stderr, fixed, rms, nobs, residual, predict, K=None, P_of_phi=None):
        self.model = model
        self.names = list(names)
        self.values = [float(v) for v in values]
        self.stderr = [float(s) for s in stderr]
        self.fixed = dict(fixed)
        self.rms = float(rms)
        self.nobs = int(nobs)
        self.residual = residual
        self.predict = predict      # x -> y of the fitted relation (phi(P) or Z(phi))
        self.K = K                  # phi -> K/E (compaction models only)
        self.P_of_phi = P_of_phi    # phi -> P/E (compaction models only)

    @property
    def params(self):
        d = dict(self.fixed)
        d.update(zip(self.names, self.values))
        return d

    def __getitem__(self, name):
        return self.params[name]

    def err(self, name):
        return dict(zip(self.names, self.stderr)).get(name, float("nan"))

    def __repr__(self):
        s = ", ".join(f"{n}={v:.6g}±{e:.2g}" for n, v, e in zip(self.names, self.values, self.stderr))
        return f"FitResult({self.model}: {s}; fixed {self.fixed}; rms {self.rms:.3g} in {self.residual})"


def _curve_fit(f, x, y, p0, bounds):
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    p0 = np.clip(np.asarray(p0, dtype=float), lo + 1e-12 * (hi - lo), hi - 1e-12 * (hi - lo))
    popt, pcov = curve_fit(f, x, y, p0=p0, bounds=(lo, hi), maxfev=20000, x_scale="jac",
                           ftol=1e-12, xtol=1e-12, gtol=1e-12)
    with np.errstate(invalid="ignore"):
        err = np.sqrt(np.diag(pcov)) if np.all(np.isfinite(pcov)) else np.full(len(popt), np.nan)
    rms = float(np.sqrt(np.mean((y - f(x, *popt)) ** 2)))
    return popt, err, rms


def _clean(P, phi, phi0):
    P = np.asarray(P, dtype=float)
    phi = np.asarray(phi, dtype=float)
    ok = np.isfinite(P) & np.isfinite(phi) & (P > 0)
    if ok.sum() < 3:
        raise ValueError("need at least 3 finite points with P > 0")
    return P[ok], phi[ok]


def _phimax_start(P, phi, phi0, phimax_hi):
    """Initial (P0, phimax) for the n = 1 logarithmic law: scan phimax, solve the
    linear least-squares for P0 in P = P0 L(phimax), keep the best residual in phi."""
    top = phi.max()
    best = None
    for pm in np.linspace(top + 1e-4 * max(top - phi0, 1e-3), phimax_hi, 400)[:-1]:
        L = -np.log(_ratio(phi, pm, phi0))
        if not np.any(L > 0):
            continue
        P0 = float(np.dot(L, P) / np.dot(L, L))
        if P0 <= 0:
            continue
        r = np.sqrt(np.mean((phi - platzer_phi(P, P0, pm, phi0)) ** 2))
        if best is None or r < best[0]:
            best = (r, P0, pm)
    if best is None:
        return 0.05, min(top + 0.05, phimax_hi)
    return best[1], best[2]


def fit_platzer(P, phi, phi0, Pstar=0.0, fit_phistar=False, phimax_hi=1.0):
    """Fit Eq. (eq:PlatzerModified2) as phi(P) with P* fixed (default 0, as the paper).
    Free: P0, phimax (and phistar if fit_phistar, otherwise phistar = phi0 as the paper).
    Bounds: P0 in (1e-8, 100), phimax in (phi0, phimax_hi], phistar in (phi0-0.2, max(phi))."""
    P, phi = _clean(P, phi, phi0)
    P0s, pms = _phimax_start(P, phi, phi0, phimax_hi)
    if fit_phistar:
        f = lambda p, P0, pm, ps: platzer_phi(p, P0, pm, ps, Pstar)
        popt, err, rms = _curve_fit(f, P, phi, (P0s, pms, phi0),
                                    ([1e-8, phi0 + 1e-9, phi0 - 0.2], [100.0, phimax_hi, phi.max()]))
        names, fixed = ["P0", "phimax", "phistar"], {"Pstar": Pstar, "phi0": phi0}
        P0, pm, ps = popt
    else:
        f = lambda p, P0, pm: platzer_phi(p, P0, pm, phi0, Pstar)
        popt, err, rms = _curve_fit(f, P, phi, (P0s, pms), ([1e-8, phi0 + 1e-9], [100.0, phimax_hi]))
        names, fixed = ["P0", "phimax"], {"Pstar": Pstar, "phistar": phi0, "phi0": phi0}
        (P0, pm), ps = popt, phi0
    return FitResult("platzer", names, popt, err, fixed, rms, len(P), "phi",
                     predict=lambda p: platzer_phi(p, P0, pm, ps, Pstar),
                     K=lambda x: platzer_K(x, P0, pm),
                     P_of_phi=lambda x: platzer_P(x, P0, pm, ps, Pstar))


def fit_secondi(P, phi, phi0, fix_n=None, phimax_hi=1.0):
    """Fit Eq. (Eq:Secondi) as phi(P).  Free: A1, n, phimax (n fixed if fix_n given).
    Bounds: A1 in (1e-10, 1e3), n in (0.05, 5), phimax in (phi0, phimax_hi].
    Start: the n = 1 (Platzer/Heuberger) solution."""
    P, phi = _clean(P, phi, phi0)
    A0, pms = _phimax_start(P, phi, phi0, phimax_hi)
    if fix_n is None:
        f = lambda p, A1, n, pm: secondi_phi(p, A1, n, pm, phi0)
        popt, err, rms = _curve_fit(f, P, phi, (A0, 1.0, pms), ([1e-10, 0.05, phi0 + 1e-9], [1e3, 5.0, phimax_hi]))
        names, fixed = ["A1", "n", "phimax"], {"phi0": phi0}
        A1, n, pm = popt
    else:
        n = float(fix_n)
        A0 = A0 ** n
        f = lambda p, A1, pm: secondi_phi(p, A1, n, pm, phi0)
        popt, err, rms = _curve_fit(f, P, phi, (A0, pms), ([1e-10, phi0 + 1e-9], [1e3, phimax_hi]))
        names, fixed = ["A1", "phimax"], {"n": n, "phi0": phi0}
        A1, pm = popt
    return FitResult("secondi", names, popt, err, fixed, rms, len(P), "phi",
                     predict=lambda p: secondi_phi(p, A1, n, pm, phi0),
                     K=lambda x: secondi_K(x, A1, n, pm, phi0),
                     P_of_phi=lambda x: secondi_P(x, A1, n, pm, phi0))


def fit_zhang(P, phi, phi0, fix_m=None, phimax_hi=1.0):
    """Fit Eq. (Eq:Zhang) as phi(P).  Free: M, m, phimax (m fixed if fix_m given).
    Bounds: M in (1e-10, 1e3), m in (0.05, 5), phimax in (phi0, phimax_hi]."""
    P, phi = _clean(P, phi, phi0)
    M0, pms = _phimax_start(P, phi, phi0, phimax_hi)
    if fix_m is None:
        f = lambda p, M, m, pm: zhang_phi(p, M, m, pm, phi0)
        popt, err, rms = _curve_fit(f, P, phi, (M0, 1.0, pms), ([1e-10, 0.05, phi0 + 1e-9], [1e3, 5.0, phimax_hi]))
        names, fixed = ["M", "m", "phimax"], {"phi0": phi0}
        M, m, pm = popt
    else:
        m = float(fix_m)
        f = lambda p, M, pm: zhang_phi(p, M, m, pm, phi0)
        popt, err, rms = _curve_fit(f, P, phi, (M0, pms), ([1e-10, phi0 + 1e-9], [1e3, phimax_hi]))
        names, fixed = ["M", "phimax"], {"m": m, "phi0": phi0}
        M, pm = popt
    return FitResult("zhang", names, popt, err, fixed, rms, len(P), "phi",
                     predict=lambda p: zhang_phi(p, M, m, pm, phi0),
                     K=lambda x: zhang_K(x, M, m, pm, phi0),
                     P_of_phi=lambda x: zhang_P(x, M, m, pm, phi0))


def fit_coordination(phi, Z, phi0, Z0=None, alpha=None):
    """Fit Eq. (Eq_Z_Phi), Z = Z0 + xi (phi - phi0)**alpha, using points with phi > phi0.
    Free: xi, alpha, and Z0 unless given (alpha fixed if given).
    Bounds: xi in (0, 1e3), alpha in (0.05, 3), Z0 in (0, 12).  Residuals in Z.
    Start: log-log regression of Z - Z0 on phi - phi0 (Z0 guess = min Z)."""
    phi = np.asarray(phi, dtype=float)
    Z = np.asarray(Z, dtype=float)
    ok = np.isfinite(phi) & np.isfinite(Z) & (phi > phi0)
    phi, Z = phi[ok], Z[ok]
    if len(phi) < 3:
        raise ValueError("need at least 3 points with phi > phi0")
    Zg = Z0 if Z0 is not None else max(Z.min() - 0.05 * (Z.max() - Z.min()) - 1e-3, 0.01)
    dz = Z - Zg
    sel = dz > 0
    if sel.sum() >= 2:
        a_s, lx_s = np.polyfit(np.log(phi[sel] - phi0), np.log(dz[sel]), 1)
        a_s, xi_s = float(np.clip(a_s, 0.1, 2.9)), float(np.exp(lx_s))
    else:
        a_s, xi_s = 0.5, 5.0
    if alpha is not None:
        a_s = float(alpha)
        xi_s = max(float(np.mean(dz / (phi - phi0) ** a_s)), 1e-3)
    names, p0, lo, hi = ["xi"], [xi_s], [1e-9], [1e3]
    if alpha is None:
        names, p0, lo, hi = names + ["alpha"], p0 + [a_s], lo + [0.05], hi + [3.0]
    if Z0 is None:
        names, p0, lo, hi = names + ["Z0"], p0 + [Zg], lo + [0.0], hi + [12.0]
    fixed = {"phi0": phi0}
    if alpha is not None:
        fixed["alpha"] = float(alpha)
    if Z0 is not None:
        fixed["Z0"] = float(Z0)

    def unpack(p):
        d = dict(fixed)
        d.update(zip(names, p))
        return d

    def f(x, *p):
        d = unpack(p)
        return coordination_Z(x, d["Z0"], d["xi"], d["alpha"], phi0)

    popt, err, rms = _curve_fit(f, phi, Z, p0, (lo, hi))
    d = unpack(popt)
    return FitResult("coordination", names, popt, err, fixed, rms, len(phi), "Z",
                     predict=lambda x: coordination_Z(x, d["Z0"], d["xi"], d["alpha"], phi0))


def fit_paper_model(P, phi, phi0, Z0, xi, alpha, b=0.14, fit_b=False, phimax_hi=1.0):
    """Fit Eq. (eq:model) as phi(P).  The paper's only free parameter is phimax
    (b from the single-particle law, Z0/xi/alpha from Eq_Z_Phi, phi0 from the jammed
    state); with fit_b=True b is fitted as well (it is strongly correlated with phimax).
    Bounds: phimax in (max(phi)*, phimax_hi], b in (1e-4, 10).
    K is returned as the paper's K2 (Eq. eq:K_predict); the exact derivative is
    paper_model_K_exact."""
    P, phi = _clean(P, phi, phi0)
    top = phi.max()
    pm_lo = phi0 + 1e-9
    # start: scan phimax for the fixed-b model
    cands = np.linspace(top + 1e-4 * max(top - phi0, 1e-3), phimax_hi, 60)[:-1]
    if len(cands) == 0:
        cands = np.array([phimax_hi])
    rs = [np.sqrt(np.mean((phi - paper_model_phi(P, pm, b, Z0, xi, alpha, phi0)) ** 2)) for pm in cands]
    pms = float(cands[int(np.argmin(rs))])
    fixed = {"Z0": Z0, "xi": xi, "alpha": alpha, "phi0": phi0}
    if fit_b:
        f = lambda p, pm, bb: paper_model_phi(p, pm, bb, Z0, xi, alpha, phi0)
        popt, err, rms = _curve_fit(f, P, phi, (pms, b), ([pm_lo, 1e-4], [phimax_hi, 10.0]))
        names = ["phimax", "b"]
        pm, bb = popt
    else:
        f = lambda p, pm: paper_model_phi(p, pm, b, Z0, xi, alpha, phi0)
        popt, err, rms = _curve_fit(f, P, phi, (pms,), ([pm_lo], [phimax_hi]))
        names = ["phimax"]
        fixed["b"] = b
        pm, bb = popt[0], b
    return FitResult("paper", names, popt, err, fixed, rms, len(P), "phi",
                     predict=lambda p: paper_model_phi(p, pm, bb, Z0, xi, alpha, phi0),
                     K=lambda x: paper_K2(x, pm, bb, Z0, xi, alpha, phi0),
                     P_of_phi=lambda x: paper_model_P(x, pm, bb, Z0, xi, alpha, phi0))


def fit_single_particle(P, phi, phi0=math.pi / 4, phimax_hi=1.0):
    """Fit Eq. (eq:evol_1P) as phi_p(P_p) (same functional form as Platzer with P* = 0):
    free b, phimax; phi_p,0 fixed (default pi/4)."""
    r = fit_platzer(P, phi, phi0, phimax_hi=phimax_hi)
    b, pm = r.values
    return FitResult("single_particle", ["b", "phimax"], r.values, r.stderr, {"phi0": phi0}, r.rms, r.nobs, "phi",
                     predict=lambda p: single_particle_phi(p, b, pm, phi0),
                     K=lambda x: single_particle_K(x, b, pm, phi0),
                     P_of_phi=lambda x: single_particle_P(x, b, pm, phi0))


def fit_phimax_mixture(kappa, phimax, phi0):
    """Fit phi1max of Eq. (Eq_toy_model_max) to (kappa, phimax) pairs with phi0 fixed.
    Bound: phi1max in (phi0, 1]."""
    kappa = np.asarray(kappa, dtype=float)
    phimax = np.asarray(phimax, dtype=float)
    f = lambda k, p1: phimax_mixture(k, phi0, p1)
    start = float(np.clip(phimax[np.argmax(kappa)], phi0 + 1e-6, 1.0))
    lo, hi = phi0 + 1e-9, 1.0
    popt, pcov = curve_fit(f, kappa, phimax, p0=[start], bounds=([lo], [hi]))
    err = np.sqrt(np.diag(pcov)) if np.all(np.isfinite(pcov)) else [np.nan]
    rms = float(np.sqrt(np.mean((phimax - f(kappa, *popt)) ** 2)))
    p1 = popt[0]
    return FitResult("phimax_mixture", ["phi1max"], popt, err, {"phi0": phi0}, rms, len(kappa), "phimax",
                     predict=lambda k: phimax_mixture(k, phi0, p1))
