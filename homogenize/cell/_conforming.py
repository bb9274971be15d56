"""Conforming tetrahedral mesh (gmsh) of a periodic cell with spheres, and its P2 homogenization.

Used to verify the voxel results: the sphere surfaces are resolved by the mesh (no staircase),
quadratic tetrahedra avoid the volumetric locking of linear ones at nu = 0.45. Periodicity: gmsh
copies the mesh of each face onto the opposite face (``setPeriodic``); every DOF of the
unfolded scikit-fem space is mapped to its periodic master by position modulo the cell, so the
fluctuation space is periodic by construction (``K_per = P^T K P``). Meant for small meshes
(~1e4-1e5 DOF, sparse direct solve); particles must not cut the cell faces.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from micro.common.validate import InputError
from micro.materials import FE, PDMS
from homogenize.cell._effective_media import lame
from homogenize.cell.problem import voigt_to_tensor
from homogenize.solvers import (AMGOptions, Deflation, block_cg, rigid_body_modes,
                                smoothed_aggregation)
from scipy.sparse.linalg import splu
from dataclasses import replace

from skfem import (Basis, BilinearForm, ElementTetP2, ElementVector, LinearForm, MeshTet,
                   MeshTet2)
from skfem.helpers import ddot, sym_grad, trace

__all__ = ["conforming_tet_mesh", "homogenize_conforming"]


def conforming_tet_mesh(box_m: float, centers_m, radii_m, mesh_size_m: float, *,
                        curvature_elements: int = 0, geometry_order: int = 1):
    """(points (M, 3) [m], tets (T, 4), phase (T,) 0 matrix / 1 particle[, midnodes]) from gmsh.

    ``curvature_elements`` > 0 refines the sphere surfaces to that many elements per 2 pi of
    curvature (gmsh ``Mesh.MeshSizeFromCurvature``), so small spheres keep their volume.
    ``geometry_order=2``: gmsh places the edge mid-nodes on the sphere surfaces (10-node
    tetrahedra); a fourth item ``midnodes`` maps each edge (sorted pair of point indices) to its
    mid-node position, so the mesh is curved and the spheres keep their volume to O(h^4)."""
    if geometry_order not in (1, 2):
        raise InputError(f"geometry_order must be 1 or 2, got {geometry_order}")
    try:
        import gmsh
    except ImportError:
        raise InputError("the conforming mesh needs gmsh (pip install gmsh)") from None
    c = np.atleast_2d(np.asarray(centers_m, dtype=float))
    r = np.atleast_1d(np.asarray(radii_m, dtype=float))
    L = float(box_m)
    if np.any(c - r[:, None] <= 0) or np.any(c + r[:, None] >= L):
        raise InputError("conforming mesh: particles must lie inside the cell (not cut its faces)")
    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("cell")
        occ = gmsh.model.occ
        box = occ.addBox(0, 0, 0, L, L, L)
        balls = [occ.addSphere(*ci, ri) for ci, ri in zip(c, r)]
        occ.fragment([(3, box)], [(3, b) for b in balls])
        occ.synchronize()
        eps = 1e-6 * L
        for d in range(3):   # opposite faces: slave at x_d = L, master at x_d = 0
            lo = [-eps] * 3 + [L + eps] * 3
            hi = list(lo)
            lo[d], lo[d + 3] = -eps, eps
            hi[d], hi[d + 3] = L - eps, L + eps
            f0 = gmsh.model.getEntitiesInBoundingBox(*lo, dim=2)
            f1 = gmsh.model.getEntitiesInBoundingBox(*hi, dim=2)
            T = np.eye(4)
            T[d, 3] = L
            gmsh.model.mesh.setPeriodic(2, [f[1] for f in f1], [f[1] for f in f0], T.ravel().tolist())
        gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size_m)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.3 * mesh_size_m)
        if curvature_elements:
            gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", int(curvature_elements))
            gmsh.option.setNumber("Mesh.MeshSizeMin", 0.0)
        gmsh.model.mesh.generate(3)
        if geometry_order == 2:
            gmsh.model.mesh.setOrder(2)          # mid-nodes snapped onto the geometry
        tags, coords, _ = gmsh.model.mesh.getNodes()
        pts = coords.reshape(-1, 3)
        index = {int(t): i for i, t in enumerate(tags)}
        tets, phase, mids = [], [], []
        ball_set = set(balls)
        etype, nn = (4, 4) if geometry_order == 1 else (11, 10)   # 4- / 10-node tetrahedron
        for dim, tag in gmsh.model.getEntities(3):
            etypes, _, enodes = gmsh.model.mesh.getElements(dim, tag)
            for et, en in zip(etypes, enodes):
                if et != etype:
                    continue
                t10 = np.array([index[int(v)] for v in en], dtype=np.int64).reshape(-1, nn)
                t = t10[:, :4]
                tets.append(t)
                if nn == 10:
                    mids.append(t10[:, 4:])
                # the fragment keeps the sphere tags for the inclusions
                inside = tag in ball_set
                if not inside:
                    cen = pts[t].mean(axis=1)
                    inside_pts = np.min(np.linalg.norm(cen[:, None, :] - c[None], axis=-1)
                                        - r[None], axis=1) < 0
                    inside = bool(np.mean(inside_pts) > 0.5)
                phase.append(np.full(t.shape[0], 1 if inside else 0))
    finally:
        gmsh.finalize()
    used = np.unique(np.concatenate(tets))
    remap = -np.ones(pts.shape[0], dtype=np.int64)
    remap[used] = np.arange(used.size)
    T = remap[np.concatenate(tets)]
    if geometry_order == 1:
        return pts[used], T, np.concatenate(phase)
    # which vertex pair each mid-node belongs to: the pair whose straight midpoint is nearest
    # (no assumption on gmsh's local edge numbering)
    P, MID = pts[used], pts[np.concatenate(mids)]
    pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    straight = np.stack([0.5 * (P[T[:, i]] + P[T[:, j]]) for i, j in pairs], axis=1)  # (T,6,3)
    d = np.linalg.norm(MID[:, :, None, :] - straight[:, None, :, :], axis=-1)          # (T,6,6)
    which = np.argmin(d, axis=2)
    midnodes = {}
    for e in range(T.shape[0]):
        for k in range(6):
            i, j = pairs[which[e, k]]
            midnodes[tuple(sorted((int(T[e, i]), int(T[e, j]))))] = MID[e, k]
    return P, T, np.concatenate(phase), midnodes


def homogenize_conforming(box_m, centers_m, radii_m, mesh_size_m, *, matrix=(PDMS.E_Pa, PDMS.nu),
                          particle=(FE.E_Pa, FE.nu), curvature_elements: int = 0,
                          geometry_order: int = 1, solver: str = "direct",
                          tol: float = 1e-9) -> dict:
    """C_eff (6x6 Voigt, Pa) of the periodic cell with P2 tetrahedra on a conforming gmsh mesh
    (``curvature_elements``, ``geometry_order``: see :func:`conforming_tet_mesh`; order 2 gives
    isoparametric P2 elements on curved sphere surfaces).

    ``solver="direct"``: sparse LU (its fill-in limits it to ~1e5 DOF on this machine);
    ``"cg"``: the six load cases in one deflated block CG (:func:`homogenize.solvers.block_cg`),
    preconditioned by pyamg smoothed aggregation with the six rigid-body modes as near-null
    space, the particles' rigid modes deflated (as the voxel solver), relative residual ``tol``;
    memory grows like the matrix, so larger meshes fit."""
    if solver not in ("direct", "cg"):
        raise InputError(f"solver must be 'direct' or 'cg', got {solver!r}")
    got = conforming_tet_mesh(box_m, centers_m, radii_m, mesh_size_m,
                              curvature_elements=curvature_elements,
                              geometry_order=geometry_order)
    pts, tets, phase = got[:3]
    L = float(box_m)
    m = MeshTet(np.ascontiguousarray(pts.T / L), np.ascontiguousarray(tets.T))           # unit cell; stiffness is scale-free in 3D up to L
    if geometry_order == 2:
        # skfem orders the phase after sorting each element's vertices; the mesh keeps the
        # element order, so the phase array still matches
        m2 = MeshTet2.from_mesh(m)
        nv = m.p.shape[1]
        doflocs = m2.doflocs.copy()
        for e in range(m.edges.shape[1]):
            key = tuple(sorted((int(m.edges[0, e]), int(m.edges[1, e]))))
            doflocs[:, nv + e] = got[3][key] / L
        m = replace(m2, doflocs=doflocs)
    basis = Basis(m, ElementVector(ElementTetP2()))
    lm, mm = lame(*matrix)
    lp, mp = lame(*particle)
    lam_e = np.where(phase == 1, lp, lm)[:, None] * np.ones((1, basis.X.shape[-1]))
    mu_e = np.where(phase == 1, mp, mm)[:, None] * np.ones((1, basis.X.shape[-1]))

    @BilinearForm
    def a(u, v, w):
        return w["lam"] * trace(sym_grad(u)) * trace(sym_grad(v)) + 2.0 * w["mu"] * ddot(sym_grad(u), sym_grad(v))

    K = a.assemble(basis, lam=lam_e, mu=mu_e)
    # periodic fold: DOF location modulo the unit cell -> master DOF
    locs = basis.doflocs.T                    # (ndof, 3); components interleaved per node
    key = np.round(np.mod(locs, 1.0) * 2 ** 20).astype(np.int64) % (2 ** 20)
    # ElementVector interleaves the components: DOFs 3k, 3k+1, 3k+2 share one location
    if not np.array_equal(locs[0::3], locs[2::3]):
        raise RuntimeError("unexpected DOF layout of ElementVector(ElementTetP2)")
    comp = np.arange(basis.N) % 3
    keys = np.column_stack([key, comp])
    _, master = np.unique(keys, axis=0, return_inverse=True)
    master = master.ravel()
    P = sp.csr_matrix((np.ones(basis.N), (np.arange(basis.N), master)),
                      shape=(basis.N, master.max() + 1))
    Kp = (P.T @ K @ P).tocsc()
    # pin the translations: first three masters of one node
    pin = np.unique(master[basis.nodal_dofs[:, 0]])
    free = np.setdiff1d(np.arange(Kp.shape[0]), pin)
    Kff = Kp[free][:, free]
    vol = basis.dx.sum(axis=1)               # element volumes (curved elements included)
    Es = [voigt_to_tensor(np.eye(6)[j], engineering=True) for j in range(6)]
    fs = []
    for E in Es:
        @LinearForm
        def rhs(v, w, E=E):
            sigE = w["lam"] * np.trace(E) * np.eye(3)[:, :, None, None] + 2.0 * w["mu"] * E[:, :, None, None]
            return -ddot(sigE, sym_grad(v))

        fs.append(P.T @ rhs.assemble(basis, lam=lam_e, mu=mu_e))
    Ff = np.stack([f[free] for f in fs], axis=1)
    W = np.zeros((Kp.shape[0], 6))
    iterations = None
    if solver == "direct":
        lu = splu(Kff.tocsc())
        W[free] = np.stack([lu.solve(Ff[:, j]) for j in range(6)], axis=1)
        del lu
    else:
        # master DOF positions (components interleaved: 3 per master node)
        mloc = np.zeros((Kp.shape[0], 3))
        mloc[master] = np.mod(locs, 1.0)
        W[free], iterations = _solve_cg(Kff.tocsr(), Ff, mloc[free], master, basis, phase,
                                        np.asarray(centers_m) / L, free, tol)
    ws = [W[:, j] for j in range(6)]
    lam_t, mu_t = np.where(phase == 1, lp, lm), np.where(phase == 1, mp, mm)
    C = np.zeros((6, 6))
    for k in range(6):
        for j in range(6):
            # <E_k : C : (E_j + eps(w_j))> = <E_k : C : E_j> - f_k . w_j  (unit cell volume)
            ckj = np.sum(vol * (lam_t * np.trace(Es[k]) * np.trace(Es[j])
                                + 2.0 * mu_t * np.sum(Es[k] * Es[j])))
            C[k, j] = (ckj - fs[k] @ ws[j]) / vol.sum()
    # Voigt stress of a unit engineering shear: the pairing with E_k (1/2 on two entries) gives
    # sigma_rc directly, so C above is already in Voigt form
    C = 0.5 * (C + C.T)
    return {"C_eff_Pa": C, "n_dof": int(Kp.shape[0]), "n_tets": int(tets.shape[0]),
            "phi_mesh": float(vol[phase == 1].sum() / vol.sum()), "solver": solver,
            "iterations": iterations}


#: smoothed aggregation of the periodic P2 system: strength threshold 0.05 (as the voxel
#: solver), pyamg's default candidate smoothing, and the sparse LU of the coarsest level, not
#: pyamg's dense pseudo-inverse (measured on the dilute-sphere P2 meshes: 45 of 63 s at 23k DOF;
#: 118k DOF 18 min / 9.3 GB -> 4 min / 3.6 GB, same C to 5e-11)
_AMG = AMGOptions(strength_theta=0.05, improve_candidates=True, coarse_solver="splu",
                  max_coarse=2000)


def _solve_cg(K, F, xyz, master, basis, phase, centres, free, tol):
    """Deflated block CG for the free DOFs of the periodic P2 system (see
    :func:`homogenize_conforming`). xyz (n_free, 3): position of each free DOF's node in the unit
    cell. Returns (W (n_free, 6), iterations per load case)."""
    n = K.shape[0]
    comp = np.asarray(free) % 3               # masters are sorted by (position, component)
    # near-null space for smoothed aggregation: the rigid modes about the cell centre
    ml = smoothed_aggregation(K, rigid_body_modes(xyz - 0.5, components=comp), _AMG)
    pre = ml.aspreconditioner(cycle="V")
    # deflation: the rigid modes of each particle at the DOFs of its elements
    dofs_elem = basis.element_dofs                           # (30, n_tets) unfolded DOFs
    free_of = -np.ones(int(master.max()) + 1, dtype=np.int64)
    free_of[free] = np.arange(n)
    rows, cols, vals = [], [], []
    part = np.flatnonzero(phase == 1)
    if part.size:
        cent = basis.mesh.p[:, basis.mesh.t[:, part]].mean(axis=1).T      # (m, 3)
        owner = np.argmin(((cent[:, None, :] - centres[None, :, :]) ** 2).sum(-1), axis=1)
        for p in np.unique(owner):
            d = np.unique(free_of[master[dofs_elem[:, part[owner == p]].ravel()]])
            d = d[d >= 0]
            modes = rigid_body_modes(xyz[d] - centres[p], components=comp[d])
            nz = np.nonzero(modes)
            rows.append(d[nz[0]]); cols.append(6 * p + nz[1]); vals.append(modes[nz])
    defl = None
    if rows:
        Z = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(n, 6 * len(centres)))
        Z = Z[:, np.flatnonzero(np.diff(Z.tocsc().indptr))]      # drop empty columns
        KZ = sp.csc_matrix(K @ Z)
        defl = Deflation(Z, KZ, splu((Z.T @ KZ).tocsc()).solve)
    W, hist = block_cg(lambda X: K @ X, lambda R: np.stack([pre @ R[:, j] for j in
                                                            range(R.shape[1])], axis=1),
                       F, tol=tol, maxiter=5000, deflation=defl)
    bad = [h[-1] for h in hist if h[-1] > tol]
    if bad:
        from micro.common.validate import ConvergenceError
        raise ConvergenceError(f"P2 block CG did not reach {tol:g} (worst {max(bad):.1e})", hist)
    return W, [len(h) - 1 for h in hist]


