"""Voxel assembly against scikit-fem's generic assembly (independent method) and basic identities."""
import numpy as np
import pytest

from homogenize.voxels import _assembly as A
from homogenize.bench.reference import skfem_reference
from homogenize.solvers import grid_node_coordinates, rigid_body_modes


@pytest.mark.parametrize("sri", [True, False])
def test_voxel_matrix_equals_skfem(sri, monkeypatch):
    monkeypatch.setattr(A, "SRI", sri)
    rng = np.random.default_rng(0)
    n, h = 4, 0.3
    lam, mu = rng.uniform(1, 3, (n, n, n)), rng.uniform(1, 2, (n, n, n))
    K = A.assemble_bsr(lam, mu, h).toarray()
    P, Ks, m = skfem_reference(lam, mu, h, sri)
    Kref = (P.T @ Ks @ P).toarray()
    # same matrix up to floating-point round-off (sums of ~64 terms of O(1))
    assert np.abs(K - Kref).max() <= 1e-13 * np.abs(Kref).max()
    # affine load -K (E x) on the unfolded mesh, folded
    E = np.array([[0.3, 0.1, 0.0], [0.1, -0.2, 0.05], [0.0, 0.05, 0.4]])
    ua = np.zeros(Ks.shape[0])
    ua[P.tocoo().row] = 0.0
    from skfem import Basis, ElementHex1, ElementVector
    nd = Basis(m, ElementVector(ElementHex1())).nodal_dofs
    ua[nd.T.ravel()] = (m.p.T @ E.T).ravel()
    fref = -(P.T @ (Ks @ ua))
    f = A.affine_load(lam, mu, h, E)
    assert np.abs(f - fref).max() <= 1e-13 * np.abs(fref).max()


def test_translations_are_the_nullspace_and_matrix_symmetric():
    rng = np.random.default_rng(1)
    n = 5
    lam, mu = rng.uniform(1, 3, (n, n, n)), rng.uniform(1, 2, (n, n, n))
    K = A.assemble_bsr(lam, mu, 0.1)
    B = rigid_body_modes(grid_node_coordinates(n))
    # periodic: rigid translations cost no energy (exactly, up to round-off)
    assert np.abs(K @ B[:, :3]).max() <= 1e-12 * abs(K).max()
    assert abs(K - K.T).max() <= 1e-14 * abs(K).max()
    assert K.has_sorted_indices


def test_body_force_load_is_consistent():
    rng = np.random.default_rng(2)
    n, h = 4, 0.5
    b = rng.normal(size=(n, n, n, 3))
    f = A.body_force_load(b, h).reshape(-1, 3)
    # total nodal force = integral of the body force (each voxel: b V)
    assert np.allclose(f.sum(axis=0), b.sum(axis=(0, 1, 2)) * h ** 3, rtol=1e-13, atol=0)
    # one loaded voxel: each of its 8 corners gets exactly V/8
    b1 = np.zeros((n, n, n, 3))
    b1[0, 0, 0] = [8.0, 0, 0]
    f1 = A.body_force_load(b1, h).reshape(-1, 3)
    assert np.count_nonzero(f1[:, 0]) == 8 and np.allclose(f1[f1[:, 0] != 0, 0], h ** 3)


def test_element_mean_strain_of_affine_increment():
    # a periodic field that is affine inside voxel (0,0,0): w = G x on its 8 corners
    n, h = 4, 0.2
    G = np.array([[0.1, 0.2, 0.0], [0.0, -0.3, 0.1], [0.05, 0.0, 0.2]])
    w = np.zeros((n ** 3, 3))
    for ax, ay, az in A.CORNERS:
        w[ax + n * (ay + n * az)] = G @ (h * np.array([ax, ay, az]))
    eps = A.element_mean_strain(w.ravel(), n, h)
    assert np.allclose(eps[0, 0, 0], 0.5 * (G + G.T), rtol=1e-12, atol=1e-14)
    # periodicity: the volume average of the strain of any periodic field vanishes
    w2 = np.random.default_rng(3).normal(size=3 * n ** 3)
    assert np.abs(A.element_mean_strain(w2, n, h).mean(axis=(0, 1, 2))).max() < 1e-12
