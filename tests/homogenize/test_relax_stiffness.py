"""The analytic magnetic stiffness of the coupled RVE (homogenize/cell/relax.py,
magnetic_stiffness_analytic) and the pseudo-transient iteration that uses it."""
import numpy as np
import pytest

from micro import RVE, InputError
from micro.dipoles import solve
from micro.materials import ElasticMaterial
from micro.particles import Monodisperse, generate_rve
from homogenize.cell import relax as R
from homogenize.cell.relax import equilibrium, green_displaceability, magnetic_stiffness_analytic

A = 2e-6                                   # sphere radius [m]
SOFT = ElasticMaterial(0.14e6, 0.49)       # Diguet's PDMS [Pa]


def _rve(n=8, seed=3, phi=0.2):
    return generate_rve(phi, n, seed, distribution=Monodisperse(A))


def _fd_stiffness(rve, B, law, demag, h_rel=1e-5):
    """dF/dx of the Ewald-summed self-consistent forces by central differences (2 dipole solves
    per column; an independent method: it never linearizes the moments)."""
    N = rve.n
    x = np.asarray(rve.centers_m)
    kw = dict(demag_factor=demag, tol=1e-13, accuracy=1e-10)
    m0 = solve(rve, B, 0.0, law, **kw).moments_Am2
    h = h_rel * A
    K = np.zeros((3 * N, 3 * N))
    for p in range(N):
        for c in range(3):
            d = np.zeros((N, 3))
            d[p, c] = h
            fp = solve(R._rve_at(rve, x + d), B, 0.0, law, initial_moments_Am2=m0,
                       **kw).total_force_N
            fm = solve(R._rve_at(rve, x - d), B, 0.0, law, initial_moments_Am2=m0,
                       **kw).total_force_N
            K[:, 3 * p + c] = ((fp - fm) / (2 * h)).ravel()
    return K


@pytest.mark.parametrize("law, B_T, demag", [("linear", 0.05, None), ("regime", 0.5, 0.362),
                                             ("frohlich-kennelly", 0.3, 1.0 / 3.0)])
def test_analytic_stiffness_matches_differences_of_ewald_forces(law, B_T, demag):
    """Implicit-function stiffness (closed-form pair kernels summed over images, moments by the
    linearized self-consistency with the law's differential susceptibility) against central
    differences of the full periodic (Ewald) self-consistent forces: equal up to the image
    cutoff of the sums, which falls as the cutoff grows (1e-3 of the largest entry at 2 box
    edges, the default); the frozen-moment part alone misses the moment response."""
    rve = _rve()
    B = np.array([0.0, 0.0, B_T])
    Kfd = _fd_stiffness(rve, B, law, demag)
    st = solve(rve, B, 0.0, law, demag_factor=demag, tol=1e-13, accuracy=1e-10)
    scale = np.abs(Kfd).max()
    errs = {}
    for cut in (1.0, 2.0, 3.0):
        K = magnetic_stiffness_analytic(rve, st, law, demag_factor=demag, cutoff_boxes=cut)
        errs[cut] = np.abs(K - Kfd).max() / scale
    assert errs[2.0] < 3e-3
    assert errs[3.0] < errs[1.0]
    # momentum conservation: the dipole forces are pairwise (Newton's third law), so a rigid
    # translation of every particle changes no force: the column sums per direction vanish
    K = magnetic_stiffness_analytic(rve, st, law, demag_factor=demag)
    N = rve.n
    for c in range(3):
        assert np.abs(K[:, c::3].sum(axis=1)).max() < 1e-9 * scale
    # frozen moments (the pair stiffness of the old Jacobian) differ by far more than that
    Kfrozen = R._dipole_pair_stiffness(np.asarray(rve.centers_m), st.moments_Am2,
                                       np.asarray(rve.radii_m), rve.box_m, near=100.0)
    assert np.abs(Kfrozen - Kfd).max() / scale > 10 * errs[2.0]


def test_analytic_stiffness_isolated_pair_closed_form():
    """Two linear spheres along the field far from their images, with moments frozen by a tiny
    susceptibility: the axial stiffness of the pair force F = -6 mu0 m^2 / (4 pi r^4) is
    dF/dr = 24 mu0 m^2 / (4 pi r^5) (open-space point dipoles)."""
    L, r = 2e-3, 12e-6
    c = np.full((2, 3), 0.5 * L)
    c[1, 2] += r
    rve = RVE.from_spheres(L, c, [A, A])
    st = solve(rve, [0, 0, 1e-3], 0.0, "linear", chi=1e-6, tol=1e-13, accuracy=1e-10)
    K = magnetic_stiffness_analytic(rve, st, "linear", {"chi": 1e-6})
    m = st.moments_Am2[0, 2]
    k = 24 * R.MU0 * m * m / (4 * np.pi * r ** 5)
    # the force on sphere 0 (below) is +6 mu0 m^2 / (4 pi r^4) along z (attraction): raising
    # sphere 1 lowers it, raising sphere 0 raises it
    assert K[2, 5] == pytest.approx(-k, rel=1e-4)
    assert K[2, 2] == pytest.approx(k, rel=1e-4)


def test_bad_stiffness_choice_refused():
    rve = _rve(4)
    M = green_displaceability(rve, SOFT)
    with pytest.raises(InputError, match="stiffness"):
        equilibrium(rve, [0, 0, 0.1], M, matrix=SOFT, stiffness="exact")


def test_analytic_and_difference_jacobians_reach_the_same_equilibrium():
    """The Jacobian only steers the iteration: with either magnetic stiffness the equilibrium is
    the same to the solver tolerance (1e-6 radii on u - M F)."""
    rve = _rve(6, seed=11, phi=0.15)
    M = green_displaceability(rve, SOFT)
    B = [0.0, 0.0, 0.2]
    kw = dict(law="regime", matrix=SOFT, demag_factor=0.362)
    e1 = equilibrium(rve, B, M, stiffness="analytic", **kw)
    e2 = equilibrium(rve, B, M, stiffness="differences", max_fd=100, **kw)
    assert np.abs(e1.displacement_m).max() > 1e-3 * A          # the field moved them
    assert np.abs(e1.displacement_m - e2.displacement_m).max() < 2e-5 * A
    assert e1.contacts == e2.contacts


def test_soft_matrix_dense_rve_converges_with_few_dipole_solves():
    """Soft matrix (0.14 MPa), phi 0.26, regime law at 0.56 T: pairs snap into contact. The
    analytic stiffness costs no dipole solve, so the whole relaxation needs one dipole solve
    per residual evaluation, and it converges without cycling."""
    rve = generate_rve(0.261, 10, 7, distribution=Monodisperse(A))
    res = R.relax(rve, [0.28, 0.56], law="regime", matrix=SOFT, demag_factor=0.362,
                  voxels=None)
    s = res.steps[-1]
    assert s["n_contacts"] >= 1 and s["min_gap_m"] > -0.05 * A
    calls = []
    orig = R.solve_dipoles

    def counting(*a, **k):
        calls.append(1)
        return orig(*a, **k)

    M = green_displaceability(rve, SOFT)
    R.solve_dipoles = counting
    try:
        e = equilibrium(rve, [0, 0, 0.28], M, law="regime", matrix=SOFT, demag_factor=0.362)
    finally:
        R.solve_dipoles = orig
    assert len(calls) == e.evaluations + 1          # + the final state's solve


def test_repeated_sweep_reuses_the_relaxation_and_gives_the_same_result():
    """relax() twice on the same RVE, steps and settings (the fine and coarse cell FEM of a
    batch's two-grid estimate): the second call reuses the relaxation (no dipole solve) and
    reports the same path; a changed setting relaxes anew."""
    c = np.array([[4, 4, 4], [4, 4, 8.3], [10, 9, 6]]) * 1e-6
    rve = RVE.from_spheres(14e-6, c, [A] * 3)
    kw = dict(law="linear", matrix=SOFT, voxels=None)
    r1 = R.relax(rve, [0.05, 0.1], **kw)
    calls = []
    orig = R.solve_dipoles

    def counting(*a, **k):
        calls.append(1)
        return orig(*a, **k)

    R.solve_dipoles = counting
    try:
        r2 = R.relax(rve, [0.05, 0.1], **kw)
        assert calls == []
        assert [s["iterations"] for s in r2.steps] == [s["iterations"] for s in r1.steps]
        assert np.array_equal(r2.rve.centers_m, r1.rve.centers_m)
        R.relax(rve, [0.05, 0.1], tol=1e-7, **kw)
        assert len(calls) > 0
    finally:
        R.solve_dipoles = orig
