"""Near-field force between two magnetizable spheres (micro/nearfield.py)."""
import math
import os

import numpy as np
import pytest
from scipy.special import lpmv

from micro import InputError
from micro.dipoles import dipole_pair_interactions
from micro.magnetization import get_law
from micro.nearfield import (MU_MAX, chord_permeability, fem_axial_polarizability,
                             multipole_order, near_field_correction_N, pair_force_N,
                             pair_polarizabilities, point_dipole_pair_force_N,
                             point_dipole_polarizabilities, translation_coefficient)

FULL = bool(os.environ.get("MAPSIM_FULL"))
ZETA3 = 1.2020569031595942


def _beta(mu):
    return 1.0 if math.isinf(mu) else (mu - 1.0) / (mu + 2.0)


@pytest.mark.parametrize("m", [0, 1])
def test_translation_theorem_both_directions(m):
    """The re-expansion coefficients reproduce an exterior harmonic about the other centre,
    evaluated directly (Legendre functions with the Condon-Shortley phase of scipy)."""
    rng = np.random.default_rng(3 + m)
    R = 1.0
    for k in (1, 2, 5):
        p = rng.normal(size=3)
        p *= 0.3 / np.linalg.norm(p)
        phi = math.atan2(p[1], p[0])
        r, ct = np.linalg.norm(p), p[2] / np.linalg.norm(p)
        ns = np.arange(m, 90)
        sg, lt = translation_coefficient(k, ns, m)
        T = sg * np.exp(lt)
        reg = r ** ns * lpmv(m, ns, ct) * math.cos(m * phi) / R ** (k + ns + 1)
        # centre 2 at +R e_z, observer near centre 1 (the origin)
        q = p - np.array([0.0, 0.0, R])
        lhs = np.linalg.norm(q) ** -(k + 1) * lpmv(m, k, q[2] / np.linalg.norm(q)) \
            * math.cos(m * phi)
        assert np.sum(T * reg) == pytest.approx(lhs, rel=1e-12, abs=1e-13)
        # centre 1 at -R e_z seen from centre 2: the parity (-1)^(k+n)
        q = p + np.array([0.0, 0.0, R])
        lhs = np.linalg.norm(q) ** -(k + 1) * lpmv(m, k, q[2] / np.linalg.norm(q)) \
            * math.cos(m * phi)
        par = np.where((k + ns) % 2 == 0, 1.0, -1.0)
        assert np.sum(par * T * reg) == pytest.approx(lhs, rel=1e-12, abs=1e-13)


@pytest.mark.parametrize("mu", [10.0, 1000.0, math.inf])
def test_large_separation_is_point_dipoles(mu):
    """Far apart, the pair polarizabilities tend to those of two self-consistent point dipoles
    (then to 2 x 4 pi a^3 beta) and the near-field correction vanishes faster than the
    dipole force (relative size ~ (a/r)^5)."""
    a = 1.0
    rel = []
    for R in (4.0, 8.0, 16.0):
        ex = np.array(pair_polarizabilities(R, a, a, mu, mu))
        pd = np.array(point_dipole_polarizabilities(R, a, a, mu, mu))
        assert np.allclose(ex[:2], pd[:2], rtol=2e-3 * (4.0 / R) ** 5)
        H = np.array([0.3, 0.0, 1.0])
        d = R * np.array([0.0, 0.6, 0.8])
        dF = near_field_correction_N(d, a, a, H, mu, mu)
        F = point_dipole_pair_force_N(d, a, a, H, mu, mu)
        rel.append(np.linalg.norm(dF) / np.linalg.norm(F))
    assert rel[-1] < 3e-5                                       # 1.4e-5 at r = 16 a
    assert rel[1] < rel[0] / 16 and rel[2] < rel[1] / 16          # ~r^-5 relative (32x)
    al = pair_polarizabilities(200.0, a, a, mu, mu)[0]
    assert al == pytest.approx(2 * 4 * math.pi * a ** 3 * _beta(mu), rel=1e-5)


def test_point_dipole_force_matches_dipole_module():
    """The co-energy derivative of the two-point-dipole polarizabilities is the force between
    the two self-consistent dipoles computed by micro.dipoles (a different route: moments from
    the 6x6 self-consistency, then F = mu0 (m . grad) H), at an oblique field."""
    a1, a2, mu1, mu2 = 1.0e-7, 0.7e-7, 50.0, 8.0
    d = np.array([0.4, -0.5, 1.3]) * 1.0e-7 * 1.6
    H = np.array([2.0e4, 5.0e3, 6.0e4])
    p = [4 * math.pi * a ** 3 * _beta(mu) for a, mu in ((a1, mu1), (a2, mu2))]
    r = np.linalg.norm(d)
    n = d / r
    T = (3 * np.outer(n, n) - np.eye(3)) / (4 * math.pi * r ** 3)   # field of a dipole
    A = np.block([[np.eye(3) / p[0], -T], [-T, np.eye(3) / p[1]]])
    m = np.linalg.solve(A, np.concatenate([H, H])).reshape(2, 3)
    _, F, _ = dipole_pair_interactions(np.array([d, [0.0, 0.0, 0.0]]), m)
    Fp = point_dipole_pair_force_N(d, a1, a2, H, mu1, mu2)
    assert np.allclose(Fp, F[0], rtol=1e-9, atol=1e-9 * np.abs(F[0]).max())
    assert np.allclose(F[0], -F[1], rtol=1e-9, atol=1e-9 * np.abs(F[0]).max())


def test_newton_third_law_unequal_spheres():
    """Force on 1 from 2 and on 2 from 1 (solved with the roles swapped: a different linear
    system) sum to zero, for unequal radii and permeabilities at an oblique field."""
    a1, a2, mu1, mu2 = 1.0, 0.6, 200.0, 15.0
    H = np.array([0.2, -0.4, 1.0])
    for gap in (0.05, 0.3, 1.0):
        d = (a1 + a2 + gap) * np.array([0.36, 0.48, 0.8])
        F1 = pair_force_N(d, a1, a2, H, mu1, mu2)
        F2 = pair_force_N(-d, a2, a1, H, mu2, mu1)
        assert np.abs(F1 + F2).max() < 1e-10 * np.abs(F1).max()
        c1 = near_field_correction_N(d, a1, a2, H, mu1, mu2)
        c2 = near_field_correction_N(-d, a2, a1, H, mu2, mu1)
        assert np.abs(c1 + c2).max() < 1e-9 * np.abs(c1).max()


def test_converged_in_the_number_of_multipoles():
    """The automatic order reaches its tolerance: doubling L changes the polarizabilities and
    their derivatives by less than 1e-8 relative, down to a gap of 1e-3 radii at mu = 1000;
    and the truncated series converges monotonically towards that value."""
    for R, mu in ((2.001, 1000.0), (2.01, math.inf), (2.1, 10.0), (3.0, 100.0)):
        *_, err = pair_polarizabilities(R, 1.0, 1.0, mu, mu, check=True)
        assert err < 1e-8
    ref = pair_polarizabilities(2.02, 1.0, 1.0, 1000.0, 1000.0)[2]
    errs = [abs(pair_polarizabilities(2.02, 1.0, 1.0, 1000.0, 1000.0, L=L)[2] / ref - 1)
            for L in (10, 20, 40, 80)]
    assert all(e2 < e1 for e1, e2 in zip(errs, errs[1:])) and errs[0] > 0.1


def test_transverse_contact_value_of_perfectly_permeable_spheres():
    """Published contact limit: two touching perfectly conducting (here: perfectly permeable)
    spheres across the field have the pair polarizability (3/2) zeta(3) in units of
    4 pi a^3 (Jeffrey 1973; Sten & Nikoskinen 1995). The multipole solution approaches it as
    the gap closes (the axial one diverges logarithmically for separate spheres)."""
    vals = [pair_polarizabilities(2.0 + g, 1.0, 1.0, math.inf, math.inf, tol=1e-8)[1]
            / (4 * math.pi) for g in (1e-2, 3e-3)]
    assert vals[1] < vals[0]
    assert vals[1] == pytest.approx(1.5 * ZETA3, rel=5e-4)
    ax = [pair_polarizabilities(2.0 + g, 1.0, 1.0, math.inf, math.inf, tol=1e-8)[0]
          for g in (1e-1, 1e-2)]
    assert ax[1] > ax[0] * 1.15


@pytest.mark.parametrize("mu, gap", [(10.0, 0.5), (1000.0, 0.1)])
def test_axial_force_against_axisymmetric_fem(mu, gap):
    """Independent full-field check: an axisymmetric magnetostatic FEM (gmsh + scikit-fem, P2)
    of the same two spheres gives the pair moment and, by central differences of a morphed
    mesh, the force (mu0/2) H0^2 d alpha_par / dr. Tolerance 0.5 % (moment) and 1 % (force):
    the FEM's own error is 0.07 % / 0.15 % at this mesh (polygonal sphere surfaces), while the
    point-dipole value differs from the exact force by 18 % (mu 10) and a factor 2.8 (mu 1000)."""
    a, R = 1.0, 2.0 + gap
    ap, _, dap, _ = pair_polarizabilities(R, a, a, mu, mu)
    h = 0.02 * gap
    al = fem_axial_polarizability(R, a, mu)
    dal = (fem_axial_polarizability(R, a, mu, morph_m=h)
           - fem_axial_polarizability(R, a, mu, morph_m=-h)) / (2 * h)
    assert al == pytest.approx(ap, rel=5e-3)
    assert dal == pytest.approx(dap, rel=1e-2)
    pd = point_dipole_polarizabilities(R, a, a, mu, mu)[2]
    assert abs(pd / dap - 1) > 0.1                   # the check can tell the models apart


def test_chord_permeability_of_the_laws():
    """Linear law: the chord permeability is 1 + chi (infinite chi capped at mu_max);
    nonlinear (soft-fk) law: mu - 1 = M / H_in with the law's own internal field."""
    V = 4 / 3 * math.pi * (25e-9) ** 3
    H = np.array([[0.0, 0.0, 1.0e4], [3.0e3, 0.0, 4.0e3]])
    ms = np.full(2, 1e9 * V)
    for chi in (5.0, 300.0):
        law = get_law("linear", chi=chi)
        mu = chord_permeability(law.moment(H, ms, V), H, V)
        assert np.allclose(mu, 1 + chi, rtol=1e-10)
    law = get_law("linear")
    assert np.all(chord_permeability(law.moment(H, ms, V), H, V) == MU_MAX)
    law = get_law("soft-fk")
    ms = np.full(2, 1.7e6 * V)
    Hs = np.array([[0.0, 0.0, 3.0e5], [0.0, 4.0e5, 3.0e5]])
    m = law.moment(Hs, ms, V)
    h = np.linalg.norm(Hs, axis=1)
    M = np.linalg.norm(m, axis=1) / V
    Hin = law.internal_field(h, ms, V)
    assert np.allclose(chord_permeability(m, Hs, V), 1 + M / Hin, rtol=1e-9)
    assert chord_permeability(np.zeros((1, 3)), np.zeros((1, 3)), V)[0] == 1.0


@pytest.mark.parametrize("call, match", [
    (lambda: pair_polarizabilities(1.9, 1.0, 1.0), "exceed"),
    (lambda: pair_polarizabilities(3.0, -1.0, 1.0), "a1_m"),
    (lambda: pair_polarizabilities(3.0, 1.0, 1.0, mu1=0.5), "mu1"),
    (lambda: pair_force_N([0, 0, 3.0], 1.0, 1.0, [0, 0, np.nan]), "H0_A_m"),
    (lambda: pair_polarizabilities(3.0, 1.0, 1.0, L=0), "L"),
])
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_order_estimate_grows_towards_contact():
    Ls = [multipole_order(2.0 + g, 1.0, 1.0, 1000.0, 1000.0) for g in (1.0, 0.1, 0.01)]
    assert Ls[0] < Ls[1] < Ls[2]
