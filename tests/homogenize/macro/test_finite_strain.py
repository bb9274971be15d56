"""Finite-strain, nearly incompressible elasticity, axisymmetric and 3D
(homogenize.macro.finite_strain).

References: the exact homogeneous uniaxial state of the material law, linear elasticity,
Lamb's incompressible sphere under p0 cos^2(theta) n (derived in ``lamb_sphere_strains``), the
first moment of the traction (mean stress, a conservation law), finite differences of the
energy and of the residual, mirror symmetry, translation, rotation and scaling, d'Alembert's
free body, the displacement formulation as the locking foil, and the axisymmetric solver as the
reference of the 3D one.
"""
import math

import numpy as np
import pytest

from homogenize.macro import finite_strain as fs
from homogenize.macro.finite_strain import (AxisymmetricBody, ConvergenceError, Loads,
                                            NeoHookeanSolid, Traction, cylinder_body,
                                            diameter_change_m, length_change_m, mean_strain,
                                            pole_strain, solve_axisymmetric, sphere_body)
from micro.materials import ElasticMaterial

G = 1.0e6                         # shear modulus [Pa] (a soft silicone)
R = 2.0e-3                        # specimen radius [m]
INC = NeoHookeanSolid.incompressible(G)


def _lamb(p0):
    """Traction p0 cos^2(theta) n = (mu0/2)(M.n)^2 n of a sphere magnetized along z: on the
    sphere cos(theta) = n_z."""
    return lambda x, n: p0 * n[1] ** 2 * n


def _rel(a, b):
    return abs(a / b - 1.0)


# ---------------------------------------------------------------------------------------------
# material law

def test_stress_is_energy_derivative_tangent_consistent_and_objective():
    rng = np.random.default_rng(3)
    H = 0.15 * rng.normal(size=(4, 3, 3))
    p = G * rng.normal(size=4)

    def W(Hm, pm):
        F = np.eye(3) + Hm
        J = np.linalg.det(F)
        return G / 2 * (J ** (-2 / 3) * np.sum(F * F, axis=(-2, -1)) - 3) + pm * (J - 1)

    P, A, Jm1, dJ = fs._material_pointwise(H, p, G)
    eps = 1e-6
    dH = rng.normal(size=(3, 3))
    # central differences: truncation ~ eps^2 ~ 1e-12, round-off ~ 1e-16 W / eps ~ 1e-10 G
    dW = (W(H + eps * dH, p) - W(H - eps * dH, p)) / (2 * eps)
    np.testing.assert_allclose(np.einsum("eij,ij->e", P, dH), dW, rtol=1e-7, atol=1e-7 * G)
    Pp, *_ = fs._material_pointwise(H + eps * dH, p, G)
    Pm, *_ = fs._material_pointwise(H - eps * dH, p, G)
    np.testing.assert_allclose(np.einsum("eijkl,kl->eij", A, dH), (Pp - Pm) / (2 * eps),
                               rtol=1e-6, atol=1e-6 * G)
    np.testing.assert_allclose(Jm1, np.linalg.det(np.eye(3) + H) - 1, rtol=1e-12, atol=1e-14)
    # dJ/dF = J F^-T (the pressure coupling)
    dJfd = (np.linalg.det(np.eye(3) + H + eps * dH) - np.linalg.det(np.eye(3) + H - eps * dH)) \
        / (2 * eps)
    np.testing.assert_allclose(np.einsum("eij,ij->e", dJ, dH), dJfd, rtol=1e-7, atol=1e-9)
    # prescribed Cauchy stress J S F^-T: tangent against central differences as well
    S = np.diag([0.3, 0.3, -0.7]) * G
    _, As = fs._prescribed_pointwise(H, S, "cauchy")
    Psp, _ = fs._prescribed_pointwise(H + eps * dH, S, "cauchy")
    Psm, _ = fs._prescribed_pointwise(H - eps * dH, S, "cauchy")
    np.testing.assert_allclose(np.einsum("eijkl,kl->eij", As, dH), (Psp - Psm) / (2 * eps),
                               rtol=1e-6, atol=1e-6 * G)
    # objectivity: P(QF) = Q P(F) for a rotation Q (exact up to round-off)
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    PQ, *_ = fs._material_pointwise(Q @ (np.eye(3) + H) - np.eye(3), p, G)
    np.testing.assert_allclose(PQ, Q @ P, rtol=1e-10, atol=1e-9 * G)


@pytest.mark.parametrize("kind", ["callable", "array"])
def test_assembled_tangent_equals_finite_differences_of_the_residual(kind):
    # the worst case: free body (multiplier), compressible, a position- and normal-dependent
    # follower traction (or a fixed vector per current area given at the facet points), a
    # dead body force and a prescribed Cauchy stress, at a deformed state
    body = sphere_body(R, 2, mid_plane=False)
    solid = NeoHookeanSolid.from_poisson(G, 0.45)
    if kind == "callable":
        trac = Traction(lambda x, n: 0.2 * G * (n[1] ** 2 + x[1] / R) * n)
    else:
        X, N = fs.facet_points(body)
        trac = Traction(0.2 * G * (N[1] ** 2 + X[1] / R) * N)
    loads = Loads((trac,), body_force_N_m3=lambda X: np.stack([0 * X[0], 1e8 * X[0] / R]),
                  prescribed_stress_Pa=np.diag([0.1, 0.1, -0.2]) * G)
    asm_ = fs._axi_assembler(body, solid, loads)
    rng = np.random.default_rng(0)
    x = np.zeros(asm_.n)
    x[asm_.free] = rng.normal(size=asm_.free.size)
    x[:asm_.nu_dof] *= 0.03 * R          # strains ~ 10 %
    x[asm_.nu_dof:] *= 0.1 * G           # pressures and multiplier
    x[asm_.fixed] = 0.0
    _, K = asm_.residual(x, 0.7)
    d = np.zeros(asm_.n)
    d[asm_.free] = rng.normal(size=asm_.free.size)
    d[:asm_.nu_dof] *= R
    d[asm_.nu_dof:] *= G
    d[asm_.fixed] = 0.0
    h = 1e-6
    rp, _ = asm_.residual(x + h * d, 0.7, tangent=False)
    rm, _ = asm_.residual(x - h * d, 0.7, tangent=False)
    fd = (rp - rm) / (2 * h)
    # central difference error ~ h^2 ~ 1e-12 relative; the traction's own derivative by
    # central differences (step 1e-6) adds ~1e-10 relative
    np.testing.assert_allclose((K @ d)[asm_.free], fd[asm_.free], rtol=0,
                               atol=1e-7 * np.abs(fd[asm_.free]).max())


# ---------------------------------------------------------------------------------------------
# homogeneous states: exact for any mesh (a linear displacement and a constant pressure lie in
# P2 x P1), so the tolerances are the Newton tolerance and round-off

@pytest.mark.parametrize("stretch", [1.1, 1.3])
def test_uniaxial_incompressible_cylinder_is_exact(stretch):
    L = 4 * R
    body = cylinder_body(R, L, 3)
    P0 = G * (stretch - stretch ** -2)           # incompressible neo-Hookean, nominal stress
    sol = solve_axisymmetric(body, INC, Loads((Traction(np.array([0.0, P0]), "end",
                                                        follower=False),)), load_steps=3)
    on_axis, face = length_change_m(sol)
    assert on_axis == pytest.approx(L * (stretch - 1), rel=1e-9)
    assert face == pytest.approx(L * (stretch - 1), rel=1e-9)
    lat = stretch ** -0.5
    assert diameter_change_m(sol) == pytest.approx(2 * R * (lat - 1), rel=1e-9)
    np.testing.assert_allclose(np.diag(mean_strain(sol)), [lat - 1, lat - 1, stretch - 1],
                               rtol=1e-9)
    # the pressure is the Cauchy mean stress sigma_zz / 3 (uniaxial): sigma_zz = P0 lambda
    np.testing.assert_allclose(sol.p_Pa, P0 * stretch / 3, rtol=1e-8)
    # deformed mesh: straight sides stay exact under a homogeneous map; volume conserved
    dm = sol.deformed_mesh()
    dbody = AxisymmetricBody(dm, "cylinder", R * lat, L * stretch / 2, True)
    assert dbody.volume_m3 == pytest.approx(body.volume_m3, rel=1e-10)
    F = fs.deformation_gradient(sol)
    np.testing.assert_allclose(F, np.broadcast_to(np.diag([lat, stretch, lat]), F.shape),
                               atol=1e-9)
    # where a follower load (or a field from the deformed body) is evaluated: the moved
    # quadrature points and the current normals (Nanson), exact for a homogeneous map
    X, N = fs.facet_points(body, "surface")
    x, n = fs.current_facet_points(sol, "surface")
    np.testing.assert_allclose(x, X * np.array([lat, stretch])[:, None, None], rtol=1e-9)
    np.testing.assert_allclose(n, N, atol=1e-12)
    assert sol.residuals[-1] < 1e-10 and sol.load_factors == (1 / 3, 2 / 3, 1.0)


def test_uniaxial_compressible_follower_traction_is_exact():
    # a Cauchy (follower) end traction at nu = 0.45 (stretch 1.32) against the exact
    # homogeneous state of the same law (bisection on two scalar equations)
    solid = NeoHookeanSolid.from_poisson(G, 0.45)
    assert fs.uniaxial_stretch(solid, 0.0) == pytest.approx((1.0, 1.0), abs=1e-12)
    sigma = G * 0.9
    la, ll = fs.uniaxial_stretch(solid, sigma, measure="cauchy")
    assert la > 1.3 and ll < 0.9
    L = 3 * R
    body = cylinder_body(R, L, 2)
    trac = Traction(lambda x, n: sigma * n[1] * np.stack([0 * n[0], np.ones_like(n[1])]),
                    "end")
    sol = solve_axisymmetric(body, solid, Loads((trac,)), load_steps=2)
    on_axis, face = length_change_m(sol)
    assert on_axis == pytest.approx(L * (la - 1), rel=1e-9)
    assert face == pytest.approx(L * (la - 1), rel=1e-9)
    assert diameter_change_m(sol) == pytest.approx(2 * R * (ll - 1), rel=1e-9)
    # incompressible closed form: nominal stress G (lambda - lambda^-2)
    la, ll = fs.uniaxial_stretch(INC, G * (1.3 - 1.3 ** -2))
    assert (la, ll) == pytest.approx((1.3, 1.3 ** -0.5), rel=1e-12)


def test_prescribed_cauchy_stress_contracts_a_free_cylinder_like_a_compression():
    # a free body with a uniform prescribed Cauchy stress diag(0, 0, s): the elastic stress
    # must be -s along z, the exact uniaxial state under the Cauchy stress -s
    s = 0.2 * G
    solid = NeoHookeanSolid.from_poisson(G, 0.49)
    L = 2 * R
    body = cylinder_body(R, L, 2, mid_plane=False)
    sol = solve_axisymmetric(body, solid, Loads(prescribed_stress_Pa=np.diag([0.0, 0.0, s])),
                             load_steps=2)
    la, ll = fs.uniaxial_stretch(solid, -s, measure="cauchy")
    on_axis, face = length_change_m(sol)
    assert on_axis == pytest.approx(L * (la - 1), rel=1e-9)
    assert face == pytest.approx(L * (la - 1), rel=1e-9)
    assert diameter_change_m(sol) == pytest.approx(2 * R * (ll - 1), rel=1e-9)
    assert abs(sol.reaction_N) < 1e-12 * s * R * R   # self-equilibrated: no net force


def test_piola_prestress_equals_dead_traction_minus_P0_N():
    # int P0 : Grad v dV = int (P0 N) . v dA: a uniform Piola prestress is the dead traction
    # -P0 N; two routes through different code, equal to the Newton tolerance
    P0 = np.diag([0.05, 0.05, 0.2]) * G
    body = sphere_body(R, 4)
    a = solve_axisymmetric(body, INC, Loads(prescribed_stress_Pa=P0,
                                            prescribed_measure="piola"))
    b = solve_axisymmetric(body, INC, Loads((Traction(
        lambda X, N: -np.stack([P0[0, 0] * N[0], P0[2, 2] * N[1]]), follower=False),)))
    np.testing.assert_allclose(a.u_m, b.u_m, rtol=0, atol=1e-10 * np.abs(b.u_m).max())


def test_varying_piola_prestress_equals_its_divergence_and_boundary_traction():
    # int P0 : Grad v dV = -int div(P0) . v dV + int (P0 N) . v dA: a prescribed stress field
    # given at the quadrature points, P0 = s1 (z/c) e_z e_z + s2 (r/R) (e_r e_r + e_t e_t), is
    # the body force div P0 and the dead traction -P0 N. In cylindrical components
    # div P0 = ((1/r) d(r P_rr)/dr - P_tt / r, dP_zz/dz) = (2 s2/R - s2/R, s1/c)
    s1, s2 = 0.2 * G, 0.1 * G
    body = cylinder_body(R, 3 * R, 3)
    c = body.half_length_m
    Xe = fs.element_points(body)
    P0 = np.zeros(Xe.shape[1:] + (3, 3))
    P0[..., 2, 2] = s1 * Xe[1] / c
    P0[..., 0, 0] = P0[..., 1, 1] = s2 * Xe[0] / R      # (x, y) = (r, theta) at y = 0
    solid = NeoHookeanSolid.from_poisson(G, 0.45)
    a = solve_axisymmetric(body, solid, Loads(prescribed_stress_Pa=P0,
                                              prescribed_measure="piola"), load_steps=2)

    def t(X, N):
        return -np.stack([s2 * X[0] / R * N[0], s1 * X[1] / c * N[1]])

    b = solve_axisymmetric(body, solid, Loads(
        (Traction(t, follower=False),),
        body_force_N_m3=np.array([s2 / R, s1 / c])), load_steps=2)
    # two routes through different code, both exact for these polynomial fields (quadrature
    # degree 4): equal to the Newton tolerance
    np.testing.assert_allclose(a.u_m, b.u_m, rtol=0, atol=1e-9 * np.abs(b.u_m).max())
    assert np.abs(a.u_m).max() > 0.01 * R                       # finite strain


def test_small_strain_compressible_cylinder_equals_linear_elasticity():
    mat = ElasticMaterial(E_Pa=3e6, nu=0.3)
    solid = NeoHookeanSolid.from_material(mat)
    assert solid.nu == pytest.approx(0.3, rel=1e-14)
    sigma = 1e-7 * mat.E_Pa          # geometric and material nonlinearity ~ 1e-7 relative
    L = 5 * R
    sol = solve_axisymmetric(cylinder_body(R, L, 2), solid, Loads((Traction(
        np.array([0.0, sigma]), "end", follower=False),)))
    assert length_change_m(sol)[0] == pytest.approx(sigma * L / mat.E_Pa, rel=1e-6)
    assert diameter_change_m(sol) == pytest.approx(-mat.nu * sigma * 2 * R / mat.E_Pa,
                                                   rel=1e-6)


# ---------------------------------------------------------------------------------------------
# Lamb's sphere (incompressible, linear regime: p0 / G = 1e-4, nonlinearity ~ 1e-5)

def test_lamb_sphere_converges_at_second_order_to_the_classical_solution():
    p0 = 1e-4 * G
    ex = fs.lamb_sphere_strains(p0, G)
    ns = (4, 8, 16)
    err_pole, err_eq, err_mean = [], [], []
    for n in ns:
        sol = solve_axisymmetric(sphere_body(R, n), INC, Loads((Traction(_lamb(p0)),)))
        err_pole.append(_rel(pole_strain(sol), ex["pole"]))
        err_eq.append(_rel(diameter_change_m(sol) / (2 * R), ex["equator"]))
        e = mean_strain(sol)
        err_mean.append(_rel(e[2, 2], ex["mean_axial"]))
        assert e[0, 0] == pytest.approx(-e[2, 2] / 2, rel=1e-3)  # incompressible, traceless
    h = [R / n for n in ns]
    # P2 on a polygonal sphere: the boundary is an O(h^2) approximation, so the rate is 2
    # (measured over n = 4, 8, 16: pole 2.12, equator 2.13, mean strain 1.95; errors at n = 16:
    # 5.0e-4, 5.3e-4, 2.9e-4; at n = 32 the rates over 8-32 are 2.09, 2.00, 2.08)
    for err in (err_pole, err_eq, err_mean):
        rate = np.polyfit(np.log(h), np.log(err), 1)[0]
        assert 1.8 < rate < 2.5, (err, rate)
    # within 1 % when converged (measured 5e-4 at n = 16)
    assert err_pole[-1] < 0.01 and err_eq[-1] < 0.01 and err_mean[-1] < 0.01
    # 5/57 of 2 p0/G at the pole; equator -1/2 of it; mean strain 1/15 of 2 p0/G
    assert ex["pole"] == pytest.approx(5 / 57 * 2 * p0 / G)
    assert ex["mean_axial"] == pytest.approx(2 * p0 / G / 15)


def test_mean_strain_equals_mean_stress_difference_over_3G():
    # conservation: int sigma dV = int X x t dA (equilibrium, no body force) and, incompressible,
    # mean(e_zz) = (mean(s_zz) - mean(s_xx)) / (3 G); it holds for the discrete solution too
    # (the tests v = z e_z, v = r e_r lie in P2; int tr(eps) dV = 0 with q = 1 in P1), so the
    # only error is the nonlinearity ~ strain ~ 1e-7 at p0 / G = 1e-6
    p0 = 1e-6 * G
    body = sphere_body(R, 6)
    sol = solve_axisymmetric(body, INC, Loads((Traction(_lamb(p0), follower=False),)))
    s = fs.traction_moment_Pa(body, _lamb(p0))
    e = mean_strain(sol)
    assert e[2, 2] == pytest.approx((s[2, 2] - s[0, 0]) / (3 * G), rel=1e-6)  # measured 2e-7
    # and the moment itself is the analytic mean stress within the polygonal surface's O(h^2)
    # (measured 0.2 % at n = 6)
    assert s[2, 2] == pytest.approx(3 * p0 / 5, rel=0.01)
    assert s[0, 0] == pytest.approx(p0 / 5, rel=0.01)


@pytest.mark.parametrize("shape", ["spheroid", "cylinder"])
def test_mean_strain_is_compliance_times_traction_moment_for_any_body(shape):
    # the same conservation law for a compressible solid (nu = 0.3) of another shape, under a
    # non-uniform normal traction: mean(eps) = ((1 + nu) mean(s) - nu tr(mean(s)) I) / E.
    # Discretely exact too (int tr(eps) q = int p q / K with q = 1), up to the nonlinearity
    # ~ strain ~ 1e-6 (measured at most 1.9e-6 relative)
    p0 = 1e-6 * G
    solid = NeoHookeanSolid.from_poisson(G, 0.3)
    E, nu = 2 * G * 1.3, 0.3
    if shape == "spheroid":
        body = fs.spheroid_body(R, 1.5 * R, 5)
    else:
        body = cylinder_body(R, 3 * R, 4)

    def t(X, N):    # (M.n)^2 n plus a pressure growing towards the ends
        return p0 * (N[1] ** 2 + (X[1] / body.half_length_m) ** 2) * N

    sol = solve_axisymmetric(body, solid, Loads((Traction(t, follower=False),)))
    s = fs.traction_moment_Pa(body, t)
    e = ((1 + nu) * s - nu * np.trace(s) * np.eye(3)) / E
    np.testing.assert_allclose(np.diag(mean_strain(sol)), np.diag(e), rtol=1e-5)


def test_no_volumetric_locking_near_incompressibility():
    # on a coarse mesh (n = 8) the compressible pole strains approach the incompressible one
    # like 1/K ~ (1 - 2 nu) / (1 + nu), the physical rate: the ratio of the differences at
    # nu = 0.49 and 0.499 is 10.06. A locking element would be far stiffer at 0.499 instead.
    p0 = 1e-4 * G
    body = sphere_body(R, 8)
    loads = Loads((Traction(_lamb(p0)),))
    s = {nu: pole_strain(solve_axisymmetric(body, NeoHookeanSolid.from_poisson(G, nu), loads))
         for nu in (0.49, 0.499)}
    s_inc = pole_strain(solve_axisymmetric(body, INC, loads))
    ratio = (s[0.49] - s_inc) / (s[0.499] - s_inc)
    expected = (0.02 / 1.49) / (0.002 / 1.499)
    # measured 10.054 against 10.060: 0.07 % (terms of order 1/K^2); 5 % leaves room for
    # other meshes, a locked element would be off by a factor
    assert ratio == pytest.approx(expected, rel=0.05)
    ex = fs.lamb_sphere_strains(p0, G)["pole"]
    assert _rel(s[0.499], ex) < 0.005     # 0.26 % physical compressibility + 0.22 % mesh
    assert _rel(s_inc, ex) < 0.005


def test_pressure_field_converges_where_the_displacement_formulation_locks():
    # Lamb's mean stress p = p0/3 + (14/19) p0 (r/R)^2 P2(cos theta) (the degree-0 part is a
    # uniform tension p0/3; the degree-2 part is -Pi with Pi = a r^2 P2, a = -(21/19) S / R^2,
    # S = 2 p0 / 3). At nu = 0.4999 the Taylor-Hood pressure converges at second order
    # (measured L2 errors 1.1e-2, 3.1e-3, 7.6e-4 at n = 4, 8, 16), as for K = inf; the plain
    # displacement formulation (P2, p = K (J - 1) at the quadrature points) is the foil: its
    # pressure is off by 123 %, 66 %, 29 % (volumetric locking of the pressure)
    p0 = 1e-4 * G
    solid = NeoHookeanSolid.from_poisson(G, 0.4999)
    loads = Loads((Traction(_lamb(p0)),))

    def p_exact(X):
        rho2 = X[0] ** 2 + X[1] ** 2
        return p0 / 3 + 14 / 19 * p0 * (1.5 * X[1] ** 2 - 0.5 * rho2) / R ** 2

    def l2(asm_, p):
        pe = p_exact(fs.element_points(asm_.body))
        return math.sqrt(np.sum(asm_.dx * (p - pe) ** 2) / np.sum(asm_.dx * pe ** 2))

    ns, err_mixed, err_disp = (4, 8, 16), [], []
    for n in ns:
        body = sphere_body(R, n)
        a = fs._axi_assembler(body, solid, loads)
        x, *_ = fs._newton(a, 1, 1e-10, 25, 2)
        err_mixed.append(l2(a, np.einsum("es,eqs->eq", x[a.pd], a.psi)))
        d = fs._axi_assembler(body, solid, loads, displacement_only=True)
        x, *_ = fs._newton(d, 1, 1e-10, 25, 2)
        err_disp.append(l2(d, solid.K_Pa * (np.linalg.det(np.eye(3) + d.grad_u(x)) - 1)))
    rate = np.polyfit(np.log([R / n for n in ns]), np.log(err_mixed), 1)[0]
    assert 1.7 < rate < 2.5, (err_mixed, rate)
    assert err_mixed[-1] < 0.01
    assert min(err_disp) > 0.2 and all(d > 25 * m for d, m in zip(err_disp, err_mixed))


def test_small_load_is_linear_and_follower_minus_dead_is_second_order():
    body = sphere_body(R, 4)
    loads = (1e-3, 1e-2, 1e-1)
    diff, lin = [], []
    s_lin = pole_strain(solve_axisymmetric(body, INC, Loads((Traction(_lamb(1e-8 * G)),))))
    s_lin /= 1e-8
    for q in loads:
        f = pole_strain(solve_axisymmetric(body, INC, Loads((Traction(_lamb(q * G)),)),
                                           load_steps=2))
        d = pole_strain(solve_axisymmetric(body, INC, Loads((Traction(_lamb(q * G),
                                                                      follower=False),)),
                                           load_steps=2))
        diff.append(abs(f - d))
        lin.append(abs(f / (q * s_lin) - 1))
    slope_diff = np.polyfit(np.log(loads), np.log(diff), 1)[0]
    slope_lin = np.polyfit(np.log(loads), np.log(lin), 1)[0]
    # both configurations agree to first order: the difference is O(load^2) (measured slope
    # 2.02) and the deviation from linearity O(load) (measured slope 1.03)
    assert slope_diff == pytest.approx(2.0, abs=0.1)
    assert slope_lin == pytest.approx(1.0, abs=0.1)
    assert diff[0] / abs(s_lin * 1e-3) < 1e-3   # measured 1.3e-4 ~ the strain


# ---------------------------------------------------------------------------------------------
# free bodies, rigid-body modes, loads as arrays

def test_free_body_equals_symmetric_quarter_and_needs_no_reaction():
    p0 = 1e-2 * G                          # finite strain ~ 2e-3
    q = solve_axisymmetric(sphere_body(R, 5), INC, Loads((Traction(_lamb(p0)),)))
    f = solve_axisymmetric(sphere_body(R, 5, mid_plane=False), INC,
                           Loads((Traction(_lamb(p0)),)))
    # the whole mesh is the quarter and its mirror image: the same discrete solution up to
    # the Newton tolerance
    assert pole_strain(f) == pytest.approx(pole_strain(q), rel=1e-8)
    np.testing.assert_allclose(mean_strain(f), mean_strain(q), rtol=1e-8, atol=1e-14)
    assert diameter_change_m(f) == pytest.approx(diameter_change_m(q), rel=1e-8)
    # self-equilibrated load: the constraint force is round-off next to the load p0 R^2
    assert abs(f.reaction_N) < 1e-9 * p0 * R * R
    # incompressible: int (J - 1) q dV = 0 for every P1 q, so the volume is kept exactly
    # (Newton tolerance) although J - 1 ~ 1e-3 pointwise is not zero at finite strain
    J = np.linalg.det(fs.deformation_gradient(f))
    dV = np.asarray(f.basis.dx) * 2 * math.pi * fs.element_points(f.body)[0]
    assert abs(np.sum((J - 1) * dV)) < 1e-10 * np.sum(dV)
    assert np.abs(J - 1).max() > 1e-5


def test_scaling_of_lengths_and_moduli():
    # the problem has no length or stress scale of its own: lengths x 10 scale u by 10, moduli
    # and loads x 3 leave u unchanged (finite strain ~ 2e-3, to the Newton tolerance)
    p0 = 1e-2 * G
    base = solve_axisymmetric(sphere_body(R, 4), INC, Loads((Traction(_lamb(p0)),)))
    big = solve_axisymmetric(sphere_body(10 * R, 4), INC, Loads((Traction(_lamb(p0)),)))
    stiff = solve_axisymmetric(sphere_body(R, 4), NeoHookeanSolid.incompressible(3 * G),
                               Loads((Traction(_lamb(3 * p0)),)))
    np.testing.assert_allclose(big.u_m, 10 * base.u_m, rtol=0,
                               atol=1e-9 * np.abs(10 * base.u_m).max())
    np.testing.assert_allclose(stiff.u_m, base.u_m, rtol=0, atol=1e-9 * np.abs(base.u_m).max())
    np.testing.assert_allclose(stiff.p_Pa, 3 * base.p_Pa, rtol=0,
                               atol=1e-9 * np.abs(3 * base.p_Pa).max())


def test_translated_free_body_has_the_same_displacement():
    # rigid-body invariance: the free sphere moved along its axis by 0.3 R, with the traction
    # moved along (the Lamb traction depends on n only), gives the same displacement field
    p0 = 1e-2 * G
    body = sphere_body(R, 4, mid_plane=False)
    mesh = body.mesh
    moved = fs._with_facets(type(mesh)(mesh.p + np.array([[0.0], [0.3 * R]]), mesh.t),
                            dict(mesh.boundaries))
    a = solve_axisymmetric(body, INC, Loads((Traction(_lamb(p0)),)))
    b = solve_axisymmetric(AxisymmetricBody(moved, "sphere", R, R, False), INC,
                           Loads((Traction(_lamb(p0)),)))
    np.testing.assert_allclose(b.u_m, a.u_m, rtol=0, atol=1e-10 * np.abs(a.u_m).max())


def test_net_axial_load_on_a_free_body_is_balanced_without_strain():
    # d'Alembert: a uniform body force accelerates a free body without deforming it; the
    # solver balances the net force by the uniform constraint force, reported as reaction_N
    f_z = 1e5                                              # [N/m^3]
    body = sphere_body(R, 4, mid_plane=False)
    sol = solve_axisymmetric(body, INC, Loads(body_force_N_m3=np.array([0.0, f_z])))
    # f R^2 / G: the displacement this force would cause if held; the solve leaves round-off
    # (Newton residual ~6e-12 relative; measured |u| / (f R^2 / G) = 1.3e-9)
    assert np.abs(sol.u_m).max() < 1e-8 * f_z * R * R / G
    assert sol.reaction_N == pytest.approx(-f_z * body.volume_m3, rel=1e-12)


def test_array_loads_at_quadrature_points_equal_callables():
    # the interface of the magnetostatic solver: values at facet / element quadrature points
    p0 = 1e-3 * G
    body = sphere_body(R, 3)
    X, N = fs.facet_points(body)
    Xe = fs.element_points(body)

    def fb(Xq):
        return np.stack([3e5 * Xq[0] / R, -2e5 * Xq[1] / R])

    a = solve_axisymmetric(body, INC, Loads((Traction(_lamb(p0), follower=False),),
                                            body_force_N_m3=fb))
    b = solve_axisymmetric(body, INC, Loads((Traction(_lamb(p0)(X, N), follower=False),),
                                            body_force_N_m3=fb(Xe)))
    np.testing.assert_allclose(a.u_m, b.u_m, rtol=0, atol=1e-12 * np.abs(a.u_m).max())
    with pytest.raises(ValueError, match="shape"):
        solve_axisymmetric(body, INC, Loads(body_force_N_m3=np.zeros((2, 3, 3))))


def test_meshes():
    # cylinder: exact volume; spheroid and sphere: polygonal, O(h^2) short of the volume
    cyl = cylinder_body(R, 3 * R, 4, mid_plane=False)
    assert cyl.volume_m3 == pytest.approx(math.pi * R ** 2 * 3 * R, rel=1e-12)
    assert set(cyl.mesh.boundaries) >= {"axis", "side", "end", "end_bottom", "surface"}
    dr = np.diff(np.unique(cyl.mesh.p[0]))
    assert dr[-1] < dr[0]                                # graded towards the rim
    sph = fs.spheroid_body(R, 2 * R, 12)
    assert sph.volume_m3 == pytest.approx(4 / 3 * math.pi * R ** 2 * 2 * R, rel=0.01)
    graded = sphere_body(R, 8, grading=1.5)                   # finer rings near the surface
    assert graded.volume_m3 == pytest.approx(4 / 3 * math.pi * R ** 3, rel=0.01)
    assert np.unique(graded.mesh.t).size == graded.mesh.p.shape[1]
    assert set(sph.mesh.boundaries) == {"axis", "mid", "surface"}
    vols = [sphere_body(R, n).volume_m3 for n in (8, 16)]
    err = [abs(v / (4 / 3 * math.pi * R ** 3) - 1) for v in vols]
    assert err[0] / err[1] == pytest.approx(4.0, rel=0.15)   # second order in h


def test_newton_failure_raises_convergence_error_with_history():
    # a compressive end load beyond what the cylinder can take in one step (nominal -5 G)
    body = cylinder_body(R, 2 * R, 2)
    loads = Loads((Traction(np.array([0.0, -5 * G]), "end", follower=False),))
    with pytest.raises(ConvergenceError) as info:
        solve_axisymmetric(body, INC, loads, max_newton=4, max_cuts=1)
    assert isinstance(info.value, RuntimeError)
    assert len(info.value.residual_history) > 0
    assert "load factor" in str(info.value)


@pytest.mark.parametrize("make, match", [
    (lambda: NeoHookeanSolid.from_poisson(G, 0.5), "Poisson"),
    (lambda: NeoHookeanSolid.from_poisson(G, -1.0), "Poisson"),
    (lambda: NeoHookeanSolid.from_poisson(G, 0.7), "Poisson"),
    (lambda: NeoHookeanSolid.from_poisson(0.0, 0.3), "shear modulus"),
    (lambda: NeoHookeanSolid(-1.0, 1e6), "shear modulus"),
    (lambda: NeoHookeanSolid(1e6, 0.0), "bulk modulus"),
    (lambda: NeoHookeanSolid.incompressible(float("nan")), "shear modulus"),
    (lambda: solve_axisymmetric(sphere_body(R, 2), INC, Loads(
        prescribed_stress_Pa=np.diag([1.0, 2.0, 3.0]))), "axisymmetric"),
    (lambda: Loads(prescribed_stress_Pa=np.eye(2)), "shape"),
    (lambda: fs.solve_3d(sphere_body(R, 2), INC, Loads()), "SolidBody"),
    (lambda: solve_axisymmetric(sphere_body(R, 2), INC, Loads((Traction(np.zeros(2), "top"),))),
     "boundary"),
    (lambda: solve_axisymmetric(sphere_body(R, 2), INC, Loads(), load_steps=[0.5, 0.3, 1.0]),
     "increasing"),
    (lambda: solve_axisymmetric(sphere_body(R, 2), INC, Loads(), load_steps=[0.5, 0.8]),
     "ending at 1"),
    (lambda: solve_axisymmetric(sphere_body(R, 2), INC, Loads(), load_steps=0), "load_steps"),
    (lambda: sphere_body(-R), "radius_m"),
])
def test_bad_input_is_refused_with_a_clear_message(make, match):
    with pytest.raises(ValueError, match=match):
        make()


# ---------------------------------------------------------------------------------------------
# three dimensions (P2/P1 tetrahedra): exact homogeneous states, free bodies, and the
# axisymmetric solver as the independent reference of a non-homogeneous problem

def test_3d_box_uniaxial_exact_with_dead_and_follower_end_traction():
    size = (2 * R, 2 * R, 4 * R)
    octant = fs.box_body(size, (1, 1, 2))
    stretch = 1.3
    P0 = G * (stretch - stretch ** -2)
    sol = fs.solve_3d(octant, INC, Loads((Traction(np.array([0.0, 0.0, P0]), "end",
                                                   follower=False),)), load_steps=2)
    on_axis, face = length_change_m(sol)
    assert on_axis == pytest.approx(4 * R * (stretch - 1), rel=1e-9)
    assert face == pytest.approx(4 * R * (stretch - 1), rel=1e-9)
    lat = stretch ** -0.5
    assert diameter_change_m(sol) == pytest.approx(2 * R * (lat - 1), rel=1e-9)
    np.testing.assert_allclose(np.diag(mean_strain(sol)), [lat - 1, lat - 1, stretch - 1],
                               rtol=1e-9)
    dm = fs.SolidBody(sol.deformed_mesh(), "box", (R, R, 2 * R), (True,) * 3)
    assert dm.volume_m3 == pytest.approx(octant.volume_m3, rel=1e-10)   # J = 1 exactly
    np.testing.assert_allclose(np.linalg.det(fs.deformation_gradient(sol)), 1.0, atol=1e-10)
    # compressible, Cauchy stress through a follower traction (current area and normal)
    solid = NeoHookeanSolid.from_poisson(G, 0.45)
    sigma = 0.5 * G
    la, ll = fs.uniaxial_stretch(solid, sigma, measure="cauchy")
    sol = fs.solve_3d(octant, solid, Loads((Traction(
        lambda x, n: sigma * n[2] * np.stack([0 * n[0], 0 * n[1], np.ones_like(n[2])]),
        "end"),)), load_steps=2)
    assert length_change_m(sol)[0] == pytest.approx(4 * R * (la - 1), rel=1e-9)
    assert diameter_change_m(sol) == pytest.approx(2 * R * (ll - 1), rel=1e-9)


def test_3d_free_box_needs_no_reaction_and_balances_a_net_load_dalembert():
    # the whole box, no symmetry plane: the six rigid modes are removed by constraints. Equal
    # and opposite end tractions: the exact uniaxial state, no reaction; adding a uniform body
    # force g changes nothing but the reaction, -g V (a freely accelerating body)
    whole = fs.box_body((2 * R, 2 * R, 4 * R), (1, 1, 2), symmetric=False)
    stretch = 1.2
    P0 = G * (stretch - stretch ** -2)

    def ends(X, N):
        return P0 * np.stack([0 * N[0], 0 * N[1], np.round(N[2])])

    g = np.array([1e6, -2e6, 3e6])                              # [N/m^3]
    a = fs.solve_3d(whole, INC, Loads((Traction(ends, follower=False),)), load_steps=2)
    b = fs.solve_3d(whole, INC, Loads((Traction(ends, follower=False),), body_force_N_m3=g),
                    load_steps=2)
    for sol in (a, b):
        on_axis, face = length_change_m(sol)
        assert on_axis == pytest.approx(4 * R * (stretch - 1), rel=1e-9)
        assert face == pytest.approx(4 * R * (stretch - 1), rel=1e-9)
        # no drift: the centre stays put (symmetric solution, int u dV = 0)
        assert np.abs(sol.displacement_m([[0.0], [0.0], [0.0]])).max() < 1e-12 * R
    scale = P0 * (2 * R) ** 2                                   # end force [N]
    assert np.abs(a.reaction_force_N).max() < 1e-9 * scale
    assert np.abs(a.reaction_moment_N_m).max() < 1e-9 * scale * R
    np.testing.assert_allclose(b.reaction_force_N, -g * whole.volume_m3, rtol=1e-9)
    # the body is centred on the origin: the uniform force has no moment about it
    assert np.abs(b.reaction_moment_N_m).max() < 1e-9 * scale * R


def test_3d_rotated_and_moved_body_gives_the_rotated_displacement():
    # objectivity of the whole discrete problem: the free box rotated by Q and shifted by c,
    # with its follower load rotated along, t'(x, n) = Q t(Q^T (x - c), Q^T n), must give
    # u'(Q X + c) = Q u(X) (finite strain ~ 10 %; equal to the Newton tolerance)
    whole = fs.box_body((2 * R, 2 * R, 3 * R), (1, 1, 1), symmetric=False)
    m = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])

    def t(x, n):     # (M.n)^2 n-like traction along m, plus a position-dependent part
        return 0.3 * G * (np.einsum("i...,i->...", n, m) ** 2 + 0.1 * x[0] / R) * n

    Q, _ = np.linalg.qr(np.random.default_rng(5).normal(size=(3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    c = np.array([0.5, -1.0, 2.0]) * R
    mesh = whole.mesh
    rot = fs._with_facets(type(mesh)(Q @ mesh.p + c[:, None], mesh.t), dict(mesh.boundaries))

    def t_rot(x, n):
        xs = np.einsum("ji,j...->i...", Q, x - c.reshape((3,) + (1,) * (x.ndim - 1)))
        return np.einsum("ij,j...->i...", Q, t(xs, np.einsum("ji,j...->i...", Q, n)))

    a = fs.solve_3d(whole, INC, Loads((Traction(t),)), load_steps=2)
    b = fs.solve_3d(fs.SolidBody(rot, "box", whole.half_extent_m, (False,) * 3), INC,
                    Loads((Traction(t_rot),)), load_steps=2)
    np.testing.assert_allclose(b.u_m, Q @ a.u_m, rtol=0, atol=1e-9 * np.abs(a.u_m).max())
    assert np.abs(a.u_m).max() > 0.05 * R


def test_3d_assembled_tangent_equals_finite_differences():
    # whole box (six multipliers), compressible, follower traction depending on x and n,
    # prescribed Cauchy stress with shear, at a random deformed state (strains ~ 5 %)
    body = fs.box_body((2 * R, 2 * R, 2 * R), (1, 1, 1), symmetric=False)
    solid = NeoHookeanSolid.from_poisson(G, 0.4)
    S = np.array([[0.1, 0.05, 0.0], [0.05, -0.1, 0.02], [0.0, 0.02, 0.3]]) * G
    loads = Loads((Traction(lambda x, n: 0.2 * G * (n[2] ** 2 + x[0] / R) * n),),
                  prescribed_stress_Pa=S)
    asm_ = fs._tet_assembler(body, solid, loads)
    assert asm_.C.shape[0] == 6
    rng = np.random.default_rng(1)
    x = np.zeros(asm_.n)
    x[:asm_.nu_dof] = 0.02 * R * rng.normal(size=asm_.nu_dof)
    x[asm_.nu_dof:] = 0.1 * G * rng.normal(size=asm_.n - asm_.nu_dof)
    _, K = asm_.residual(x, 0.8)
    d = np.concatenate([R * rng.normal(size=asm_.nu_dof),
                        G * rng.normal(size=asm_.n - asm_.nu_dof)])
    h = 1e-6
    fd = (asm_.residual(x + h * d, 0.8, tangent=False)[0]
          - asm_.residual(x - h * d, 0.8, tangent=False)[0]) / (2 * h)
    # central differences ~ h^2 relative, the traction's own derivative ~ 1e-10 relative
    np.testing.assert_allclose(K @ d, fd, rtol=0, atol=1e-7 * np.abs(fd).max())


def test_3d_cylinder_converges_to_the_axisymmetric_solution():
    # independent method: a quarter cylinder of tetrahedra against the axisymmetric solver on
    # a fine mesh, under a non-homogeneous load (the magnetized-cylinder traction p0 n_z^2 n on
    # the ends and a radial body force f0 r / R), nu = 0.49, strains ~ 2 %. The 3D section is a
    # polygon of m segments per quarter: its area falls short by O(1/m^2) and so do the mean
    # strain and the end-face mean displacement (measured 2.6 %, 1.6 %, 0.83 % at m = 4, 5, 7,
    # rate 2.04, each within 0.1 % of the area deficit). The reference (n = 12) is within 3e-7
    # of n = 24.
    L, p0, f0 = 4 * R, 0.1 * G, 0.2 * G / R
    solid = NeoHookeanSolid.from_poisson(G, 0.49)
    ref = solve_axisymmetric(cylinder_body(R, L, 12), solid, Loads(
        (Traction(lambda x, n: p0 * n[1] ** 2 * n),),
        body_force_N_m3=lambda X: np.stack([f0 * X[0] / R, 0 * X[1]])))
    e_ref, face_ref = mean_strain(ref)[2, 2], length_change_m(ref)[1]
    m, err_e, err_face = [], [], []
    for n_r in (2, 3, 4):
        body = fs.cylinder_body_3d(R, L, n_r, 2)
        sol = fs.solve_3d(body, solid, Loads(
            (Traction(lambda x, n: p0 * n[2] ** 2 * n),),
            body_force_N_m3=lambda X: np.stack([f0 * X[0] / R, f0 * X[1] / R, 0 * X[2]])))
        m.append(math.ceil(n_r * math.pi / 2))
        err_e.append(_rel(mean_strain(sol)[2, 2], e_ref))
        err_face.append(_rel(length_change_m(sol)[1], face_ref))
    for err in (err_e, err_face):
        rate = np.polyfit(np.log(1.0 / np.array(m)), np.log(err), 1)[0]
        assert 1.6 < rate < 2.5, (err, rate)
        assert err[-1] < 0.015


def test_solve_3d_warm_start_reaches_the_same_state():
    """solve_3d(initial=...) (the 3D specimen's staggered iteration): Newton from a solution
    under nearby loads reaches the same equilibrium as from the undeformed body (to Newton's
    tolerance, 1e-10 of the load: 1e-8 of u relative), in fewer iterations."""
    body = fs.cylinder_body_3d(1e-3, 1.6e-3, 3)
    solid = fs.NeoHookeanSolid.from_poisson(1e5, 0.49)

    def loads(p):
        return fs.Loads((fs.Traction(lambda x, n: p * n[2] ** 2 * n, "surface"),))
    near = fs.solve_3d(body, solid, loads(2.0e3), load_steps=2)
    cold = fs.solve_3d(body, solid, loads(2.2e3), load_steps=2)
    warm = fs.solve_3d(body, solid, loads(2.2e3), initial=near)
    np.testing.assert_allclose(warm.u_m, cold.u_m, rtol=0, atol=1e-8 * np.abs(cold.u_m).max())
    assert warm.newton_iterations < cold.newton_iterations
    from micro.common.validate import InputError
    with pytest.raises(InputError, match="initial"):
        fs.solve_3d(fs.cylinder_body_3d(1e-3, 1.6e-3, 2), solid, loads(1e3), initial=near)
