"""Self-consistent moments, forces and effective quantities of RVEs (micro.dipoles.solve)."""
import math

import numpy as np
import pytest
from scipy.constants import mu_0 as MU0

from micro import RVE, ConvergenceError, InputError, applied_gradient, get_law, solve
from micro.dipoles import FieldConfig, magnetize
from micro.particles import generate_rve

A = 25e-9                                         # particle radius [m]
V = 4 / 3 * math.pi * A ** 3
MS = 7870 * 178 * V                               # Fe, seed paper [A m^2]


def _rve(centers, box, radius=A):
    n = len(centers)
    r = np.full(n, radius)
    return RVE(box_m=box, centers_m=np.asarray(centers), radii_m=r, core_radii_m=r,
               m_sat_Am2=np.full(n, 7870 * 178 * 4 / 3 * math.pi * radius ** 3),
               mass_kg=np.full(n, 7870 * 4 / 3 * math.pi * radius ** 3),
               cluster_id=np.full(n, -1, dtype=np.int64), seed=None, params={})


def _cubic(n, box):
    g = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    return (g + 0.5) * box / n


def test_cubic_lattice_clausius_mossotti_exact_and_demag():
    """Point dipoles on a cubic lattice feel exactly H + M/3 (Lorentz): M = 3 phi/(1-phi) H for
    m = 3 V H_loc; with a demagnetizing factor N the internal field is H_a - N M."""
    box = 4 * 4 * A                       # 4^3 particles, spacing 4 radii: phi = 0.0654
    rve = _rve(_cubic(4, box), box)
    phi = rve.phi
    B = 1e-3                              # 3 V H << m_s: the cap is far away
    st = solve(rve, B, 0.0, "linear", accuracy=1e-10, tol=1e-12)
    chi = 3 * phi / (1 - phi)
    np.testing.assert_allclose(st.M_eff_A_per_m, [0, 0, chi * B / MU0], rtol=1e-9,
                               atol=1e-9 * chi * B / MU0)
    for N in (1 / 3, 1.0):
        st = solve(rve, B, 0.0, "linear", accuracy=1e-10, tol=1e-12, demag_factor=N)
        assert st.M_eff_A_per_m[2] == pytest.approx(chi / (1 + N * chi) * B / MU0, rel=1e-9)


def test_clausius_mossotti_random_dispersion():
    """Linear law at phi = 0.05: composite susceptibility ~ 3 phi / (1 - phi).

    Measured spread between N = 250 samples is ~1 %, and the pair-correlation (phi^2)
    correction of the point-dipole model is ~1 % here: 3 % on the mean of three samples."""
    chis, cms = [], []
    for seed in range(3):
        rve = generate_rve(0.05, 250, seed)
        st = solve(rve, 1e-3, 0.0, "linear")
        chis.append(st.M_eff_A_per_m[2] * MU0 / 1e-3)
        cms.append(3 * rve.phi / (1 - rve.phi))
    assert np.mean(chis) == pytest.approx(np.mean(cms), rel=0.03)
    assert np.all(np.abs(np.array(chis) / cms - 1) < 0.05)


@pytest.fixture(scope="module")
def clustered():
    return generate_rve(0.05, 150, 11, arrangement="clusters", cluster_size=8)


def test_saturated_seed_formula_exact(clustered):
    rve = clustered
    st = solve(rve, 0.1, 1.78, "saturated")
    rho, sig = 7870.0, 178.0
    # f_eff = phi rho sigma_s gradB along z for homogeneous Fe spheres. Exact up to the tilt of
    # the applied field across the box (|G| L / |B| ~ 1e-5 rad, cos - 1 ~ 1e-11): 1e-10.
    assert st.f_eff_N_m3[2] == pytest.approx(rve.phi * rho * sig * 1.78, rel=1e-10)
    # transverse: first order in the tilt (1e-5) times -1/2 gradB, averaging out over the box
    np.testing.assert_allclose(st.f_eff_N_m3[:2], 0, atol=1e-5 * st.f_eff_N_m3[2])
    assert st.phi_eff == pytest.approx(rve.phi, rel=1e-10)
    assert st.d_eff == pytest.approx(rve.phi / 0.035, rel=1e-10)
    assert st.dd_force_sum_rel < 1e-10
    _check_torque_balance(st, rve)


def _dd_torque_density(st, rve):
    B, G = st.B_applied_T, st.gradient_T_per_m
    H_app = (B + (rve.centers_m - rve.box_m / 2) @ G.T) / MU0
    return MU0 * np.cross(st.moments_Am2, st.H_local_A_m - H_app).sum(0) / rve.volume_m3


def _check_torque_balance(st, rve):
    """Angular momentum balance of the pair interactions: the antisymmetric part of the virial
    stress is the dipole-dipole torque density, sigma_ab - sigma_ba = eps_abc tau_c / V (it
    vanishes, i.e. sigma is symmetric, when the dd torques cancel). 1e-6: PME/Ewald accuracy."""
    S = st.virial_stress_Pa
    tau = _dd_torque_density(st, rve)
    anti = np.array([S[1, 2] - S[2, 1], S[2, 0] - S[0, 2], S[0, 1] - S[1, 0]])
    np.testing.assert_allclose(anti, tau, atol=1e-6 * np.abs(S).max())


@pytest.mark.parametrize("law", ["linear", "frohlich-kennelly"])
def test_newton_third_law_and_identities(clustered, law):
    st = solve(clustered, 0.1, 1.78, law)
    assert st.dd_force_sum_rel < 1e-10
    assert st.residual <= 1e-8
    # moments follow the law in their converged local field
    lw = get_law(law)
    m = lw.moment(st.H_local_A_m, clustered.m_sat_Am2, clustered.particle_volumes_m3)
    np.testing.assert_allclose(st.moments_Am2, m, atol=1e-7 * np.abs(m).max())
    # f_eff = G M_eff for a uniform gradient (forces are G m_i)
    _, G = applied_gradient(0.1, 1.78)
    np.testing.assert_allclose(st.f_eff_N_m3, G @ st.M_eff_A_per_m, rtol=1e-12)
    _check_torque_balance(st, clustered)


@pytest.mark.parametrize("law", ["linear", "frohlich-kennelly", "langevin"])
def test_induced_dipole_force_is_minus_energy_gradient(law):
    """F = mu0 (m.grad) H equals -grad U with U = -mu0 int_0^|H| m dh (finite difference);
    for the linear law it is half of the naive grad(mu0 m.H) at fixed m = alpha H."""
    box = 2e-5                             # one particle: images add V/L^3 ~ 1e-8 relative
    x0 = np.array([0.3, 0.6, 0.45]) * box
    rve = _rve([x0], box, radius=A if law != "langevin" else 5e-9)
    Bv = np.array([0.002, -0.001, 0.004])  # weak: the linear law stays below its cap
    G = np.array([[0.3, 1.1, -0.4], [1.1, -0.8, 0.7], [-0.4, 0.7, 0.5]]) * 1e3   # T/m
    st = solve(rve, Bv, G, law, accuracy=1e-10, tol=1e-12)
    lw = get_law(law)
    vol, ms = rve.particle_volumes_m3, rve.m_sat_Am2
    xc = np.full(3, box / 2)

    def U(x):
        h = np.linalg.norm(Bv + G @ (x - xc)) / MU0
        return -lw.coenergy_J(h, ms[0], vol[0])

    dx = 1e-4 * box       # U is smooth on the scale |B|/|G| ~ 4 um: FD error ~1e-8
    grad = np.array([(U(x0 + dx * e) - U(x0 - dx * e)) / (2 * dx) for e in np.eye(3)])
    F = st.force_ext_N[0]
    np.testing.assert_allclose(F, -grad, rtol=1e-5, atol=1e-6 * np.abs(grad).max())
    if law == "linear":
        # naive: U = -mu0 m.H with m = alpha H gives grad(mu0 alpha |H|^2)
        # = 2 alpha G^T B / mu0 (alpha = 3 V, H = B / mu0): twice the true force
        naive = 2 * 3 * vol[0] * G.T @ (Bv + G @ (x0 - xc)) / MU0
        np.testing.assert_allclose(naive, 2 * F, rtol=1e-5)


def _chains(direction, n_chain=4, per_side=3):
    """Chains of n_chain touching spheres along x or z on a per_side^2 lattice of lines."""
    box = per_side * 2 * A * n_chain * 1.0
    cs = []
    for i in range(per_side):
        for j in range(per_side):
            for k in range(n_chain):
                p = [(i + 0.5) * box / per_side, (j + 0.5) * box / per_side, (k + 0.5) * 2 * A]
                cs.append(p if direction == "z" else [p[2], p[1], p[0]])
    return _rve(cs, box)


def test_chains_along_and_across_field():
    """Linear law: chains along the field carry more moment per particle than a dispersion at
    the same phi, chains across the field less (values printed for the report)."""
    along, across = _chains("z"), _chains("x")
    B = 1e-3
    m0 = 3 * V * B / MU0                  # isolated particle
    res = {}
    for name, rve in (("along", along), ("across", across)):
        st = solve(rve, B, 0.0, "linear", tol=1e-10)
        res[name] = st.moments_Am2[:, 2].mean() / m0
    from micro.particles import Monodisperse
    vals = []
    for seed in range(2):
        d = generate_rve(along.phi, along.n, seed, distribution=Monodisperse(A))
        vals.append(solve(d, B, 0.0, "linear", tol=1e-10).moments_Am2[:, 2].mean() / m0)
    res["dispersed"] = float(np.mean(vals))
    # infinite touching chain, point dipoles: m/m0 = 1/(1 - 2 zeta(3)/8 * 2) ~ 2.5 along,
    # 1/(1 + zeta(3)/4) ~ 0.77 across; finite chains of 4 lie between these and 1
    assert res["along"] > 1.3 * res["dispersed"]
    assert res["across"] < 0.9 * res["dispersed"]
    assert 0.9 < res["dispersed"] < 1.2           # ~1 + phi: Lorentz field of a dispersion
    print("moment per particle / isolated:", res)


def test_same_seed_and_permutation(clustered):
    rve = clustered
    a = solve(rve, 0.05, 1.78, "frohlich-kennelly")
    b = solve(rve, 0.05, 1.78, "frohlich-kennelly")
    np.testing.assert_array_equal(a.moments_Am2, b.moments_Am2)
    np.testing.assert_array_equal(a.virial_stress_Pa, b.virial_stress_Pa)
    perm = np.random.default_rng(5).permutation(rve.n)
    rp = RVE(box_m=rve.box_m, centers_m=rve.centers_m[perm], radii_m=rve.radii_m[perm],
             core_radii_m=rve.core_radii_m[perm], m_sat_Am2=rve.m_sat_Am2[perm],
             mass_kg=rve.mass_kg[perm], cluster_id=rve.cluster_id[perm], seed=rve.seed,
             params=rve.params)
    c = solve(rp, 0.05, 1.78, "frohlich-kennelly")
    # converged to tol 1e-8 along possibly different rounding paths: 1e-6 relative
    np.testing.assert_allclose(c.moments_Am2, a.moments_Am2[perm], atol=1e-6 * np.abs(a.moments_Am2).max())
    np.testing.assert_allclose(c.f_eff_N_m3, a.f_eff_N_m3, rtol=1e-7)
    np.testing.assert_allclose(c.virial_stress_Pa, a.virial_stress_Pa, atol=1e-6 * np.abs(a.virial_stress_Pa).max())


def test_anderson_needs_at_most_half_the_evaluations(clustered):
    fp = solve(clustered, 0.05, 0.0, "linear", method="fixed-point")
    an = solve(clustered, 0.05, 0.0, "linear", method="anderson")
    np.testing.assert_allclose(an.moments_Am2, fp.moments_Am2, atol=1e-6 * np.abs(fp.moments_Am2).max())
    assert an.field_evaluations <= 0.5 * fp.field_evaluations, (an.field_evaluations, fp.field_evaluations)


def test_preconditioned_solvers_agree_and_count(clustered):
    """Anderson with and without the near-field preconditioner, and preconditioned
    Newton-Krylov, reach the fixed point of the plain iteration (Froehlich-Kennelly, where the
    preconditioner is rebuilt once at the first self-consistent field)."""
    kw = dict(accuracy=1e-8, tol=1e-10)
    fp = solve(clustered, 0.05, 1.78, "frohlich-kennelly", method="fixed-point", damping=0.9,
               **kw)
    scale = np.abs(fp.moments_Am2).max()
    counts = {}
    for method, pre in (("anderson", True), ("anderson", False), ("newton-krylov", True)):
        st = solve(clustered, 0.05, 1.78, "frohlich-kennelly", method=method,
                   precondition=pre, **kw)
        # both converged to 1e-10 relative residual; contraction ~0.5: 1e-8 between them
        np.testing.assert_allclose(st.moments_Am2, fp.moments_Am2, atol=1e-8 * scale)
        counts[(method, pre)] = st.field_evaluations
    # measured: 12 preconditioned, 16 plain Anderson, 23 damped fixed point (0.52), 52
    # Newton-Krylov (each Jacobian product costs a field evaluation)
    assert counts[("anderson", True)] < counts[("anderson", False)], counts
    assert counts[("anderson", True)] <= 0.6 * fp.field_evaluations, (counts, fp.iterations)


def test_near_field_matrix_and_law_jacobian():
    """T_near m is the bare dipole field of the near pairs (direct sum), across the periodic
    boundary too; the law Jacobian dm/dH matches central differences of law.moment."""
    from micro.dipoles import _law_jacobian, _NearFieldPreconditioner, dipole_field_direct
    box = 40 * A
    c = np.array([[2 * A, 3 * A, 5 * A], [2 * A, 3 * A, 7.2 * A],     # gap 0.2 A < A/2
                  [0.3 * A, 20 * A, 20 * A], [box - 1.5 * A, 20 * A, 20.5 * A],  # across x = 0
                  [20 * A, 10 * A, 10 * A]])                         # isolated
    rve = _rve(c, box)
    lw = get_law("frohlich-kennelly")
    pc = _NearFieldPreconditioner(c, box, rve.radii_m, lw, rve.m_sat_Am2,
                                  rve.particle_volumes_m3)
    assert pc.n_pairs == 2
    m = np.random.default_rng(1).normal(size=(5, 3)) * MS
    h = (pc.T @ m.ravel()).reshape(5, 3)
    cw = c.copy()
    cw[3, 0] -= box                                                   # nearest image
    ref = np.zeros((5, 3))
    for grp in ([0, 1], [2, 3]):
        ref[grp] = dipole_field_direct(cw[grp], m[grp], cw[grp])
    np.testing.assert_allclose(h, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    H = np.random.default_rng(2).normal(size=(5, 3)) * 3e4
    D = _law_jacobian(lw, H, rve.m_sat_Am2, rve.particle_volumes_m3)
    e = 1e-3                               # A/m, on fields ~3e4 A/m: FD error ~1e-9 relative
    for k in range(3):
        dH = np.zeros(3)
        dH[k] = e
        fd = (lw.moment(H + dH, rve.m_sat_Am2, rve.particle_volumes_m3)
              - lw.moment(H - dH, rve.m_sat_Am2, rve.particle_volumes_m3)) / (2 * e)
        np.testing.assert_allclose(D[:, :, k], fd, rtol=1e-6, atol=1e-6 * np.abs(D).max())


def test_langevin_pair_below_and_above_the_coupling_limit():
    """Two particles on the field axis, Langevin law at 300 K in a weak field. Below
    lambda = 3/2 the solve converges to the scalar pair equation
    m = m_s L(mu0 m_s (H + 2 m / (4 pi d^3)) / kT); above it the law is refused with one
    message naming the coupling parameter and the superparamagnetic assumption."""
    from scipy.constants import k as KB
    from scipy.optimize import brentq
    from micro.magnetization import _langevin
    d = 10e-9
    box = 200 * d                     # images: (d/L)^3 ~ 1e-7 of the neighbour field
    T = 300.0

    def pair(lam):
        ms = math.sqrt(lam * 4 * math.pi * d ** 3 * KB * T / MU0)
        r = np.full(2, 4e-9)
        return RVE(box_m=box, centers_m=np.array([[0.5, 0.5, 0.5], [0.5, 0.5, 0.5 + d / box]])
                   * box, radii_m=r, core_radii_m=r, m_sat_Am2=np.full(2, ms),
                   mass_kg=np.full(2, 1e-21), cluster_id=np.full(2, -1, dtype=np.int64),
                   seed=None, params={}), ms

    rve, ms = pair(1.2)
    H0 = 0.3 * KB * T / (MU0 * ms)            # Langevin argument 0.3 from the applied field
    st = solve(rve, MU0 * H0, 0.0, "langevin", accuracy=1e-10, tol=1e-12)
    b = MU0 * ms / (KB * T)
    y = brentq(lambda y: y - _langevin(b * (H0 + 2 * y * ms / (4 * math.pi * d ** 3))), 0, 1,
               xtol=1e-15)
    m = y * ms
    # images of the pair shift the field by ~(d/L)^3 = 1.25e-7 relative
    np.testing.assert_allclose(st.moments_Am2[:, 2], m, rtol=1e-6)
    rve, ms = pair(1.6)
    with pytest.raises(InputError, match="lambda .* reaches 1.6.*superparamagnet"):
        solve(rve, MU0 * H0, 0.0, "langevin")


def test_langevin_refuses_25nm_iron():
    """The reported failure: 25 nm Fe spheres (lambda ~ 1e3) under the Langevin law give one
    InputError naming the physics instead of a non-convergence after 500 iterations."""
    rve = _rve(_cubic(3, 3 * 2.2 * A), 3 * 2.2 * A)
    with pytest.raises(InputError, match="law 'langevin' is not valid.*lambda.*blocked"):
        solve(rve, 0.01, 1.78, "langevin")


def test_nonconvergence_is_an_error_with_history(clustered):
    with pytest.raises(ConvergenceError) as exc:
        solve(clustered, 0.05, 1.78, "linear", method="fixed-point", max_iter=3)
    assert len(exc.value.residual_history) == 3
    assert "did not converge" in str(exc.value)


def test_bad_input(clustered):
    with pytest.raises(InputError, match="law"):
        solve(clustered, 0.1, 1.78, "curie")
    with pytest.raises(InputError, match="traceless"):
        solve(clustered, 0.1, np.eye(3), "linear")
    with pytest.raises(InputError, match="demag_factor"):
        solve(clustered, 0.1, 1.78, "linear", demag_factor=2)
    with pytest.raises(InputError, match="B_T"):
        solve(clustered, [0.1, 0.2], 1.78, "linear")
    with pytest.raises(InputError, match="rve"):
        solve(object(), 0.1, 1.78, "linear")


def test_magnetize_stage_equals_solve(clustered):
    """The typed stage is the solver with its configuration: same numbers to round-off."""
    cfg = FieldConfig(B_T=(0.0, 0.0, 0.1), gradB_T_per_m=1.78, law="frohlich-kennelly")
    st = magnetize(clustered, cfg)
    ref = solve(clustered, 0.1, 1.78, "frohlich-kennelly")
    np.testing.assert_allclose(st.f_eff_N_m3, ref.f_eff_N_m3, rtol=1e-12)
    np.testing.assert_allclose(st.total_force_N, ref.force_ext_N + ref.force_dd_N, rtol=1e-12)
    with pytest.raises(InputError, match="tol"):
        FieldConfig(tol=2.0)
    with pytest.raises(InputError, match="method"):
        FieldConfig(method="magic")
