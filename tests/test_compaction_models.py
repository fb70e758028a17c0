#!/usr/bin/python3
"""Tests of scripts/compaction_models.py: synthetic curves from each model with
known parameters (some with small noise) must be recovered by the fit helpers,
and K = phi dP/dphi by finite differences must match the analytic derivatives.

Run:  /usr/bin/python3 tests/test_compaction_models.py
Prints 'N passed, N failed' and exits non-zero on any failure.
"""
import math
import os
import sys
import traceback

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scripts"))
import compaction_models as cm  # noqa: E402

PHI0 = 0.835
PRESS = np.geomspace(1e-4, 0.5, 30)
RESULTS = []


def close(name, got, want, rtol=0.0, atol=0.0):
    ok = abs(got - want) <= atol + rtol * abs(want)
    if not ok:
        raise AssertionError(f"{name}: got {got:.8g}, want {want:.8g} (rtol {rtol}, atol {atol})")


def test(fn):
    def run():
        try:
            fn()
            RESULTS.append((fn.__name__, True, ""))
            print(f"PASS {fn.__name__}")
        except Exception as e:  # noqa: BLE001
            RESULTS.append((fn.__name__, False, str(e)))
            print(f"FAIL {fn.__name__}: {e}")
            traceback.print_exc()
    run.__name__ = fn.__name__
    TESTS.append(run)
    return fn


TESTS = []
rng = np.random.default_rng(12345)


@test
def platzer_exact_recovery():
    P0, pm = 0.08, 0.93
    phi = cm.platzer_phi(PRESS, P0, pm, PHI0)
    r = cm.fit_platzer(PRESS, phi, PHI0)
    close("P0", r["P0"], P0, rtol=1e-6)
    close("phimax", r["phimax"], pm, atol=1e-8)
    assert r.rms < 1e-10, r.rms


@test
def platzer_noisy_recovery():
    P0, pm = 0.17, 0.88
    phi = cm.platzer_phi(PRESS, P0, pm, PHI0) + rng.normal(0, 2e-4, PRESS.size)
    r = cm.fit_platzer(PRESS, phi, PHI0)
    close("P0", r["P0"], P0, rtol=0.05)
    close("phimax", r["phimax"], pm, atol=2e-3)
    assert 1e-4 < r.rms < 4e-4, r.rms
    # the quoted standard errors should be consistent with the actual errors
    assert abs(r["P0"] - P0) < 5 * r.err("P0"), (r["P0"], r.err("P0"))


@test
def platzer_P_inverse_and_sign():
    P0, pm, ps, Ps = 0.1, 0.95, 0.85, 0.01
    phi = cm.platzer_phi(PRESS, P0, pm, ps, Ps)
    np.testing.assert_allclose(cm.platzer_P(phi, P0, pm, ps, Ps), PRESS, rtol=1e-8, atol=1e-12)
    assert np.all(np.diff(cm.platzer_P(np.linspace(0.86, 0.94, 9), P0, pm, ps, Ps)) > 0)


@test
def platzer_original_matches_simplified():
    # Eq. (eq:PlatzerOriginal) with rigid sand, e(0,P) = 1 - phi0 constant, equals
    # Eq. (eq:PlatzerModified2) with phistar = phi0 + kappa f*, phimax = phi0 + kappa F.
    kappa, fstar, F, P0, Ps = 0.5, 0.02, 0.2, 0.1, 0.003
    P = PRESS[PRESS >= Ps]
    e = cm.platzer_original_void_ratio(P, kappa, 1 - PHI0, fstar, F, P0, Ps)
    phi = cm.platzer_phi(P, P0, PHI0 + kappa * F, PHI0 + kappa * fstar, Ps)
    np.testing.assert_allclose(1 - e, phi, rtol=0, atol=1e-14)


@test
def secondi_recovery_n_free():
    A1, n, pm = 0.05, 0.8, 0.97
    phi = cm.secondi_phi(PRESS, A1, n, pm, PHI0)
    r = cm.fit_secondi(PRESS, phi, PHI0)
    close("A1", r["A1"], A1, rtol=1e-4)
    close("n", r["n"], n, rtol=1e-4)
    close("phimax", r["phimax"], pm, atol=1e-6)
    np.testing.assert_allclose(cm.secondi_P(phi, A1, n, pm, PHI0), PRESS, rtol=1e-8)


@test
def secondi_noisy_recovery():
    A1, n, pm = 0.06, 1.2, 0.95
    phi = cm.secondi_phi(PRESS, A1, n, pm, PHI0) + rng.normal(0, 1e-4, PRESS.size)
    r = cm.fit_secondi(PRESS, phi, PHI0)
    close("n", r["n"], n, rtol=0.08)
    close("A1", r["A1"], A1, rtol=0.15)
    close("phimax", r["phimax"], pm, atol=2e-3)


@test
def secondi_n1_equals_platzer():
    phi = np.linspace(0.84, 0.96, 13)
    np.testing.assert_allclose(cm.secondi_P(phi, 0.07, 1.0, 0.97, PHI0), cm.platzer_P(phi, 0.07, 0.97, PHI0),
                               rtol=1e-13)
    r = cm.fit_secondi(PRESS, cm.platzer_phi(PRESS, 0.07, 0.97, PHI0), PHI0, fix_n=1.0)
    close("A1", r["A1"], 0.07, rtol=1e-6)


@test
def zhang_recovery_m_free():
    M, m, pm = 0.05, 1.3, 0.96
    phi = cm.zhang_phi(PRESS, M, m, pm, PHI0)
    np.testing.assert_allclose(cm.zhang_P(phi, M, m, pm, PHI0), PRESS, rtol=1e-8)
    close("phi(P->0)", float(cm.zhang_phi(1e-14, M, m, pm, PHI0)), PHI0, atol=1e-9)
    r = cm.fit_zhang(PRESS, phi, PHI0)
    close("M", r["M"], M, rtol=1e-4)
    close("m", r["m"], m, rtol=1e-4)
    close("phimax", r["phimax"], pm, atol=1e-6)


@test
def zhang_noisy_recovery_m_fixed():
    M, pm = 0.079, 0.96
    phi = cm.zhang_phi(PRESS, M, 1.0, pm, PHI0) + rng.normal(0, 2e-4, PRESS.size)
    r = cm.fit_zhang(PRESS, phi, PHI0, fix_m=1.0)
    close("M", r["M"], M, rtol=0.06)
    close("phimax", r["phimax"], pm, atol=3e-3)


@test
def coordination_recovery():
    Z0, xi, alpha = 4.0, 5.1, 0.5
    phi = np.linspace(PHI0 + 1e-3, 0.96, 25)
    Z = cm.coordination_Z(phi, Z0, xi, alpha, PHI0)
    r = cm.fit_coordination(phi, Z, PHI0)
    close("Z0", r["Z0"], Z0, atol=1e-5)
    close("xi", r["xi"], xi, rtol=1e-5)
    close("alpha", r["alpha"], alpha, rtol=1e-5)
    Zn = Z + rng.normal(0, 0.02, Z.size)
    r = cm.fit_coordination(phi, Zn, PHI0, Z0=Z0)
    close("xi (noisy, Z0 fixed)", r["xi"], xi, rtol=0.05)
    close("alpha (noisy, Z0 fixed)", r["alpha"], alpha, rtol=0.06)
    r = cm.fit_coordination(phi, Zn, PHI0, Z0=Z0, alpha=0.5)
    close("xi (noisy, Z0 and alpha fixed)", r["xi"], xi, rtol=0.02)
    close("xi_from_max", cm.xi_from_max(Z0 + xi * (0.96 - PHI0) ** alpha, Z0, 0.96, PHI0, alpha), xi, rtol=1e-12)


@test
def paper_model_recovery():
    b, Z0, xi, alpha, pm = 0.14, 4.0, 5.1, 0.5, 0.93
    phi = cm.paper_model_phi(PRESS, pm, b, Z0, xi, alpha, PHI0)
    np.testing.assert_allclose(cm.paper_model_P(phi, pm, b, Z0, xi, alpha, PHI0), PRESS, rtol=1e-7)
    r = cm.fit_paper_model(PRESS, phi, PHI0, Z0, xi, alpha, b=b)
    close("phimax", r["phimax"], pm, atol=1e-7)
    noisy = phi + rng.normal(0, 2e-4, phi.size)
    r = cm.fit_paper_model(PRESS, noisy, PHI0, Z0, xi, alpha, b=b)
    close("phimax (noisy)", r["phimax"], pm, atol=1e-3)
    r = cm.fit_paper_model(PRESS, phi, PHI0, Z0, xi, alpha, b=0.1, fit_b=True)
    close("phimax (b free)", r["phimax"], pm, atol=1e-5)
    close("b (b free)", r["b"], b, rtol=1e-3)


@test
def single_particle_recovery():
    b, pm = 0.14, 0.98
    P = np.linspace(0.005, 0.5, 40)
    phi = cm.single_particle_phi(P, b, pm) + rng.normal(0, 1e-4, P.size)
    r = cm.fit_single_particle(P, phi)
    close("b", r["b"], b, rtol=0.02)
    close("phimax", r["phimax"], pm, atol=1e-3)


@test
def mixture_rule():
    phi0, p1 = 0.84, 0.97
    close("kappa=0", float(cm.phimax_mixture(0.0, phi0, p1)), phi0, rtol=1e-14)
    close("kappa=1", float(cm.phimax_mixture(1.0, phi0, p1)), p1, rtol=1e-14)
    # volume additivity: 1/phi = (1-kappa)/phi0 + kappa/phi1
    k = np.array([0.2, 0.5, 0.8])
    np.testing.assert_allclose(1 / cm.phimax_mixture(k, phi0, p1), (1 - k) / phi0 + k / p1, rtol=1e-13)
    kk = np.array([0.2, 0.5, 0.8, 1.0])
    r = cm.fit_phimax_mixture(kk, cm.phimax_mixture(kk, phi0, p1) + np.array([1e-4, -1e-4, 5e-5, 0]), phi0)
    close("phi1max", r["phi1max"], p1, atol=3e-4)


def _fd_check(name, P_of_phi, K_an, lo, hi, rtol):
    """K = phi dP/dphi from a densely sampled synthetic curve (two FD schemes)."""
    phi = np.linspace(lo, hi, 4001)
    P = P_of_phi(phi)
    K_fd = cm.bulk_modulus_fd(P, phi)
    np.testing.assert_allclose(K_fd[5:-5], K_an(phi)[5:-5], rtol=rtol, err_msg=name + " (gradient)")
    # compact's midpoint formula, compared at the midpoints
    K_mid = cm.bulk_modulus_midpoint(P, phi, phi_start=None)[1:]
    mid = 0.5 * (phi[1:] + phi[:-1])
    np.testing.assert_allclose(K_mid[5:-5], K_an(mid)[5:-5], rtol=rtol, err_msg=name + " (midpoint)")


@test
def bulk_modulus_finite_differences():
    lo, hi = PHI0 + 2e-3, 0.95
    _fd_check("platzer", lambda x: cm.platzer_P(x, 0.08, 0.96, PHI0), lambda x: cm.platzer_K(x, 0.08, 0.96),
              lo, hi, 1e-5)
    _fd_check("secondi", lambda x: cm.secondi_P(x, 0.05, 0.8, 0.96, PHI0),
              lambda x: cm.secondi_K(x, 0.05, 0.8, 0.96, PHI0), lo, hi, 1e-4)
    _fd_check("zhang", lambda x: cm.zhang_P(x, 0.05, 1.3, 0.96, PHI0),
              lambda x: cm.zhang_K(x, 0.05, 1.3, 0.96, PHI0), lo, hi, 1e-4)
    args = (0.96, 0.14, 4.0, 5.1, 0.5, PHI0)
    _fd_check("paper exact", lambda x: cm.paper_model_P(x, *args), lambda x: cm.paper_model_K_exact(x, *args),
              lo, hi, 1e-4)
    _fd_check("single particle", lambda x: cm.single_particle_P(x, 0.14, 0.98),
              lambda x: cm.single_particle_K(x, 0.14, 0.98), math.pi / 4 + 1e-3, 0.97, 1e-5)


@test
def bulk_modulus_from_phi_of_P_and_eps_v():
    # sample phi(P) on a pressure grid (as compact does), then K = dP/deps_v with
    # eps_v = -ln(phi0/phi) must equal phi dP/dphi analytically.
    P0, pm = 0.1, 0.95
    P = np.geomspace(1e-4, 0.5, 3000)
    phi = cm.platzer_phi(P, P0, pm, PHI0)
    eps_v = -np.log(PHI0 / phi)
    K_eps = np.gradient(P, eps_v, edge_order=2)
    np.testing.assert_allclose(K_eps[3:-3], cm.platzer_K(phi, P0, pm)[3:-3], rtol=2e-4)


@test
def paper_K2_is_leading_term():
    # K2 = Z phi/(2 pi) K_p  (Eq. eq:K_Kp), and the exact derivative of eq:model
    # differs from K2 only by the -(b phi/2pi)(Z + phi Z') ln r term.
    args = (0.96, 0.14, 4.0, 5.1, 0.5, PHI0)
    phi = np.linspace(PHI0 + 1e-3, 0.955, 50)
    Z = cm.coordination_Z(phi, 4.0, 5.1, 0.5, PHI0)
    np.testing.assert_allclose(cm.paper_K2(phi, *args), Z * phi / (2 * math.pi) * cm.single_particle_K(phi, 0.14, 0.96),
                               rtol=1e-13)
    diff = cm.paper_model_K_exact(phi, *args) - cm.paper_K2(phi, *args)
    lnr = np.log((0.96 - phi) / (0.96 - PHI0))
    dZ = 5.1 * 0.5 * (phi - PHI0) ** -0.5
    np.testing.assert_allclose(diff, -(0.14 * phi / (2 * math.pi)) * (Z + phi * dZ) * lnr, rtol=1e-10)
    assert np.all(diff > 0)


@test
def voigt_K1_limit():
    phi = PHI0 * (1 + 1e-12)
    close("K1(phi0)", float(cm.voigt_K1(phi, 4.0, 4.0, PHI0)), 4.0 * PHI0 / (2 * math.pi), rtol=1e-9)


@test
def infer_phi0_from_first_row():
    phi0, P1, phi1 = 0.8412, 1e-4, 0.8417
    K1 = float(cm.bulk_modulus_midpoint([P1], [phi1], phi_start=phi0)[0])
    close("phi0", cm.infer_phi0(P1, phi1, K1), phi0, rtol=1e-12)
    assert cm.infer_phi0(P1, phi1, float("inf")) is None


def main():
    for t in TESTS:
        t()
    npass = sum(1 for r in RESULTS if r[1])
    nfail = len(RESULTS) - npass
    print(f"{npass} passed, {nfail} failed")
    return 1 if nfail else 0


if __name__ == "__main__":
    sys.exit(main())
