"""Large-deformation (neo-Hookean, total Lagrangian) cantilever against the elastica."""

import numpy as np
import pytest
from scipy.optimize import brentq

from homogenize.macro import closed_form as cf
from homogenize.macro.cantilever import Strip, solve_cantilever
from homogenize.macro.fem import Material, _neo_hookean_pointwise, _NeoHookeanAssembler, \
    vector_basis
from homogenize.macro.cantilever import _mesh

MAT = Material(2e6, 0.45)
STRIP = Strip(1.0, 0.05, 0.05)
DIV = (21, 2, 3)   # k = 3 of the convergence family: linear tip within 0.2 % of EB


def test_stress_is_objective_and_tangent_consistent():
    rng = np.random.default_rng(1)
    lam, mu = MAT.lame_Pa
    H = 0.2 * rng.normal(size=(5, 3, 3))
    P, A = _neo_hookean_pointwise(H, lam, mu)
    # rotate the deformed configuration: P(Q F) = Q P(F)
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    PQ, _ = _neo_hookean_pointwise(Q @ (np.eye(3) + H) - np.eye(3), lam, mu)
    np.testing.assert_allclose(PQ, Q @ P, rtol=1e-10, atol=1e-6 * mu)
    # tangent = derivative of P, central differences (error ~ eps^2 ~ 1e-12 relative)
    dH = rng.normal(size=(3, 3))
    eps = 1e-6
    Pp, _ = _neo_hookean_pointwise(H + eps * dH, lam, mu)
    Pm, _ = _neo_hookean_pointwise(H - eps * dH, lam, mu)
    np.testing.assert_allclose(np.einsum("...ijkl,kl->...ij", A, dH), (Pp - Pm) / (2 * eps),
                               rtol=1e-6, atol=1e-6 * mu)


def test_assembled_tangent_is_linear_elasticity_at_rest():
    from skfem import asm
    from skfem.models.elasticity import linear_elasticity
    basis = vector_basis(_mesh(STRIP, (4, 1, 1)), 2)
    lam, mu = MAT.lame_Pa
    r, K = _NeoHookeanAssembler(basis, lam, mu, np.zeros(3)).internal(np.zeros(basis.N))
    K0 = asm(linear_elasticity(lam, mu), basis)
    assert np.abs(r).max() == 0.0
    assert abs(K - K0).max() < 1e-12 * abs(K0).max()


def test_small_load_equals_linear():
    f = 10.0  # tip/L ~ 3e-3: geometric nonlinearity ~ (tip/L)^2 ~ 1e-5
    lin = solve_cantilever(STRIP, MAT, f, divisions=DIV).tip_m
    nl = solve_cantilever(STRIP, MAT, f, divisions=DIV, model="neo-hookean", n_steps=1)
    assert nl.tip_m == pytest.approx(lin, rel=1e-3)


def test_agrees_with_elastica_at_tip_over_length_0_3():
    q_per_f = STRIP.width_m * STRIP.thickness_m
    EI = MAT.E_Pa * STRIP.width_m * STRIP.thickness_m**3 / 12
    alpha = brentq(lambda a: cf.elastica_shooting(a)[0] - 0.3, 1.0, 6.0, xtol=1e-12)
    f = alpha * EI / (q_per_f * STRIP.length_m**3)
    v, h = cf.elastica_tip_deflection(f, STRIP.length_m, STRIP.width_m, STRIP.thickness_m,
                                      MAT.E_Pa)
    assert v == pytest.approx(0.3, rel=1e-8)
    nl = solve_cantilever(STRIP, MAT, f, divisions=DIV, model="neo-hookean", clamp="beam",
                          n_steps=3)
    lin = solve_cantilever(STRIP, MAT, f, divisions=DIV, clamp="beam").tip_m
    eb = cf.eb_tip_deflection_m(f, STRIP.length_m, STRIP.width_m, STRIP.thickness_m, MAT.E_Pa)
    # 3D neo-Hookean vs 1D inextensible elastica: shear (0.3 %), discretisation (0.2 %) and
    # axial strain (~1e-3) separate them -> within 1 %
    assert nl.tip_m == pytest.approx(v, rel=0.01)
    # the nonlinear/linear ratio cancels the common 3D and mesh factors
    assert nl.tip_m / lin == pytest.approx(v / eb, rel=0.005)
    assert nl.tip_horizontal_m == pytest.approx(h, rel=0.03)
    assert nl.solver == "newton" and nl.iterations <= 25


def test_vectorised_assembly_equals_scikit_fem_forms():
    # independent assembly of the same law: scikit-fem's own dof maps and quadrature loops
    from homogenize.macro.fem import _skfem_neo_hookean
    basis = vector_basis(_mesh(STRIP, (3, 1, 1)), 2)
    lam, mu = MAT.lame_Pa
    u = 2e-3 * np.random.default_rng(2).normal(size=basis.N)   # strains ~ 0.1: nonlinear
    r1, K1 = _NeoHookeanAssembler(basis, lam, mu, np.zeros(3)).internal(u)
    r0, K0 = _skfem_neo_hookean(basis, u, lam, mu)
    assert np.abs(r1 - r0).max() < 1e-10 * np.abs(r0).max()   # round-off only
    assert abs(K1 - K0).max() < 1e-10 * abs(K0).max()
