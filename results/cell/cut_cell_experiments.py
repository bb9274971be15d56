"""Cut-cell experiments for issue 15's "dilute rate about second order": why composite voxels are
first order at Fe/PDMS contrast, and a discretization of the same voxel grid that is second order.

The experimental discretizations live in this script, not in mapsim (like coarse_space_experiments).
All use the project's periodic Q1 voxel grid (homogenize._assembly: node i + n (j + n k), SRI
element in the voxels that no interface cuts) and a nodal level set phi (< 0: iron, > 0: PDMS).
A voxel is CUT when its corner values change sign; its 6 Kuhn tetrahedra (all along the main
diagonal, so the faces match between voxels) are split exactly by the plane of the linear
interpolant of phi, which gives the discrete interface (planar facets, O(h^2) from the sphere).

Methods compared:
- "composite": the project's default, Reuss voxels at the exact cut fraction (homogenize.cell).
- "xfem-ridge": Q1 + the ridge enrichment of Moes, Cloirec, Cartraud & Remacle (2003),
  psi = sum_a N_a |phi_a| - |phi_h|, 3 extra unknowns per node of a cut voxel.
- "nitsche": two Q1 copies in every cut voxel, one per phase, integrated over that phase's part
  (Hansbo & Hansbo 2002), glued on the facets by a symmetric Nitsche method with contrast-robust
  weights w_i = (V_i / E_i) / sum_j (V_j / E_j) (Annavarapu, Hautefeuille & Dolbow 2012) and a
  penalty 2 sum_i w_i^2 lambda_i per voxel, lambda_i the largest eigenvalue of the traction
  energy on the facets against the copy's bulk energy (the coercivity bound, computed per voxel).
  The volumetric term of each copy acts on its mean divergence over its part (B-bar: the cut
  voxel's analogue of the one-point volumetric rule of the full voxels; with the full rule the
  cut layer locks: +10.1 % instead of +0.9 % at 4.3 voxels per diameter, nominal radius, one
  offset, one-off). The level set of a sphere is the distance to its centre minus a radius
  chosen so that the discrete particle holds the exact particle volume ("volume-matched"; the
  nominal radius loses 11 % of the volume at 4.3 voxels per diameter and 2.7 % at 8.6, which
  hides part of the error: rows with volume_matched false in the JSON).

Experiments:
1. Tilted periodic Fe/PDMS laminate, normal (1, 1, 1)/sqrt 3, Fe fraction 0.5, against the exact
   rank-one laminate (homogenize._assembly.laminate_voigt): the relative error of the energy of
   C_eff along each eigenvector of the exact one (3 soft modes, 3 stiff).
2. One dilute Fe sphere per periodic PDMS cell (phi 0.01, the cell of dilute_rate.py): the shear
   coefficient c = (G / G_m - 1) / phi against that study's curved-P2 limit 2.3408 +- 0.0056, at
   random sphere-centre offsets (dilute_rate.py's seed), and the observed order.

Run:  .venv/bin/python results/cell/cut_cell_experiments.py          (~25 min, peak ~5 GB)
      .venv/bin/python results/cell/cut_cell_experiments.py --quick  (~1 min; JSON to /tmp)
      --plot-only redraws cut_cell_experiments.png from the JSON.
"""
from __future__ import annotations

import argparse
import itertools
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyamg
import scipy.sparse as sp

from homogenize import _assembly as asm
from homogenize.cell import homogenize_mesh, voigt_to_tensor
from homogenize.mesh import VoxelMesh
from micro.materials import FE, PDMS, elastic

HERE = Path(__file__).resolve().parent
JSON = HERE / "cut_cell_experiments.json"
FE_EL, PDMS_EL = elastic(FE), elastic(PDMS)
PHI = 0.01
RADIUS = (3.0 * PHI / (4.0 * np.pi)) ** (1.0 / 3.0)         # [box]
P2_LIMIT, P2_ERR = 2.3408, 0.0056                            # dilute_rate.json
SEED = 20261124                                              # dilute_rate.py's offsets
LAMINATE_NORMAL = (1, 1, 1)
LAMINATE_F = 0.5
LAMINATE_SHIFT = 0.3    # [voxels along m . (i, j, k)]: keeps every node off the interfaces

CORN = asm.CORNERS.astype(float)       # local corner a = x + 2 y + 4 z -> (x, y, z)
KUHN = np.array([[0] + [sum(1 << d for d in perm[:k + 1]) for k in range(3)]
                 for perm in itertools.permutations(range(3))])   # 6 x 4 corner indices


# ------------------------------------------------------------------------------------------------
# geometry and quadrature
# ------------------------------------------------------------------------------------------------

def _gauss01(q):
    x, w = np.polynomial.legendre.leggauss(q)
    return 0.5 * (x + 1.0), 0.5 * w


def tet_rule(q):
    """Collapsed (Duffy) Gauss rule on a tetrahedron: barycentric points (Q, 4), weights (Q,)
    as fractions of the volume."""
    x, w = _gauss01(q)
    a, b, c = (g.ravel() for g in np.meshgrid(x, x, x, indexing="ij"))
    wa, wb, wc = (g.ravel() for g in np.meshgrid(w, w, w, indexing="ij"))
    lam = np.stack([1 - a, a * (1 - b), a * b * (1 - c), a * b * c], axis=1)
    return lam, wa * wb * wc * a ** 2 * b * 6.0


def tri_rule(q):
    """Collapsed Gauss rule on a triangle: barycentric points (Q, 3), area fractions (Q,)."""
    x, w = _gauss01(q)
    a, b = (g.ravel() for g in np.meshgrid(x, x, indexing="ij"))
    wa, wb = (g.ravel() for g in np.meshgrid(w, w, indexing="ij"))
    return np.stack([1 - a, a * (1 - b), a * b], axis=1), wa * wb * a * 2.0


def split_tet(P, phi):
    """Split tetrahedron P (4, 3) by the zero plane of the linear phi (4,): sub-tetrahedra
    [(4, 3), sign], interface triangles [(3, 3)] and the unit normal towards phi > 0."""
    neg = phi < 0
    k = int(neg.sum())
    if k in (0, 4):
        return [(P, -1 if k == 4 else 1)], [], None
    g = np.linalg.solve(P[1:] - P[0], phi[1:] - phi[0])

    def cut(i, j):
        return P[i] + phi[i] / (phi[i] - phi[j]) * (P[j] - P[i])

    def prism(T1, T2):
        return [np.array([T1[0], T1[1], T1[2], T2[0]]), np.array([T1[1], T1[2], T2[0], T2[1]]),
                np.array([T1[2], T2[0], T2[1], T2[2]])]
    if k in (1, 3):
        lone_sign = -1 if k == 1 else 1
        a = int(np.flatnonzero(neg if k == 1 else ~neg)[0])
        others = [i for i in range(4) if i != a]
        cp = [cut(a, o) for o in others]
        parts = [(np.array([P[a]] + cp), lone_sign)]
        parts += [(t, -lone_sign) for t in prism(cp, [P[o] for o in others])]
        return parts, [np.array(cp)], g / np.linalg.norm(g)
    a, b = np.flatnonzero(neg)
    c, d = np.flatnonzero(~neg)
    pac, pad, pbc, pbd = cut(a, c), cut(a, d), cut(b, c), cut(b, d)
    parts = [(t, -1) for t in prism([P[a], pac, pad], [P[b], pbc, pbd])]
    parts += [(t, 1) for t in prism([P[c], pac, pbc], [P[d], pad, pbd])]
    return parts, [np.array([pac, pad, pbd]), np.array([pac, pbd, pbc])], g / np.linalg.norm(g)


def q1(xi):
    """Q1 shape functions N (..., 8) and d N / d xi (..., 8, 3) of the unit cube."""
    x, y, z = xi[..., 0, None], xi[..., 1, None], xi[..., 2, None]
    cx, cy, cz = CORN[:, 0], CORN[:, 1], CORN[:, 2]
    fx = cx * x + (1 - cx) * (1 - x)
    fy = cy * y + (1 - cy) * (1 - y)
    fz = cz * z + (1 - cz) * (1 - z)
    dN = np.stack([(2 * cx - 1) * fy * fz, fx * (2 * cy - 1) * fz, fx * fy * (2 * cz - 1)], -1)
    return fx * fy * fz, dN


def cut_pieces(phi_c):
    """Sub-tetrahedra (S, 4, 3) [voxel units], their voxel and sign, and interface triangles
    (T, 3, 3), their voxel and normal, of cut voxels with corner values phi_c (m, 8)."""
    subs, sown, ssg, tris, town, tnrm = [], [], [], [], [], []
    for v in range(phi_c.shape[0]):
        for t in KUHN:
            parts, faces, nrm = split_tet(CORN[t], phi_c[v, t])
            for P, s in parts:
                subs.append(P), sown.append(v), ssg.append(s)
            for T in faces:
                tris.append(T), town.append(v), tnrm.append(nrm)
    return (np.array(subs), np.array(sown), np.array(ssg), np.array(tris).reshape(-1, 3, 3),
            np.array(town, dtype=np.int64), np.array(tnrm).reshape(-1, 3))


def tet_negative_volume(P, ph):
    """Volume (T,) of {phi < 0} in tetrahedra P (T, 4, 3) with vertex values ph (T, 4)."""
    vol = np.abs(np.linalg.det(P[:, 1:] - P[:, :1])) / 6.0
    neg = ph < 0
    k = neg.sum(axis=1)
    out = np.where(k == 4, vol, 0.0)
    for kk, lone_neg in ((1, True), (3, False)):
        sel = np.flatnonzero(k == kk)
        if sel.size:
            lone = np.argmax(neg[sel] if lone_neg else ~neg[sel], axis=1)
            pa = ph[sel, lone]
            frac = np.ones(sel.size)
            for o in range(4):
                other = lone != o
                frac[other] *= pa[other] / (pa[other] - ph[sel, o][other])
            out[sel] = vol[sel] * (frac if lone_neg else 1.0 - frac)
    sel = np.flatnonzero(k == 2)
    if sel.size:
        order = np.argsort(~neg[sel], axis=1, kind="stable")          # negatives first
        Ps = np.take_along_axis(P[sel], order[:, :, None], axis=1)
        ps = np.take_along_axis(ph[sel], order, axis=1)

        def cut(i, j):
            return Ps[:, i] + (ps[:, i] / (ps[:, i] - ps[:, j]))[:, None] * (Ps[:, j] - Ps[:, i])

        def tv(x0, x1, x2, x3):
            return np.abs(np.linalg.det(np.stack([x1 - x0, x2 - x0, x3 - x0], axis=1))) / 6.0
        a, b = Ps[:, 0], Ps[:, 1]
        pac, pad, pbc, pbd = cut(0, 2), cut(0, 3), cut(1, 2), cut(1, 3)
        out[sel] = tv(a, pac, pad, b) + tv(pac, pad, b, pbc) + tv(pad, b, pbc, pbd)
    return out


def _grid(n):
    k, j, i = np.meshgrid(*(np.arange(n),) * 3, indexing="ij")
    nodes = np.stack([((i + ax) % n + n * (((j + ay) % n) + n * ((k + az) % n))).ravel()
                      for ax, ay, az in asm.CORNERS], axis=1)               # (n^3, 8)
    return np.stack([i, j, k], axis=-1) / n, nodes


def nodal_phi(phi_fn, n):
    x, nodes = _grid(n)
    phi = phi_fn(x).ravel()
    return np.where(phi == 0.0, 1e-12 / n, phi), nodes


def discrete_volume(phi_fn, n):
    """Volume [box^3] of {phi_h < 0} (the Kuhn-linear interpolant) on the n^3 grid."""
    phi, nodes = nodal_phi(phi_fn, n)
    pc = phi[nodes]
    nneg = (pc < 0).sum(axis=1)
    cut = np.flatnonzero((nneg > 0) & (nneg < 8))
    P = np.broadcast_to(CORN[KUHN], (cut.size, 6, 4, 3)).reshape(-1, 4, 3)
    vals = pc[cut][:, KUHN].reshape(-1, 4)
    return ((nneg == 8).sum() + tet_negative_volume(P, vals).sum()) / n ** 3


def sphere_fn(centre, radius):
    def phi(x):
        d = x - centre
        return np.linalg.norm(d - np.round(d), axis=-1) - radius
    return phi


def volume_matched_radius(centre, n, radius=RADIUS):
    """Radius whose discrete sphere (Kuhn-linear interface) holds 4/3 pi radius^3 (secant)."""
    target = 4.0 / 3.0 * np.pi * radius ** 3
    r0, r1 = radius, 1.02 * radius
    v0, v1 = (discrete_volume(sphere_fn(centre, r), n) for r in (r0, r1))
    for _ in range(12):
        r0, v0, r1 = r1, v1, r1 + (target - v1) * (r1 - r0) / (v1 - v0)
        v1 = discrete_volume(sphere_fn(centre, r1), n)
        if abs(v1 / target - 1.0) < 1e-11:
            break
    return r1


# ------------------------------------------------------------------------------------------------
# cut-voxel matrices
# ------------------------------------------------------------------------------------------------

def _iso_K(G, lam, mu):
    """(..., 3F, 3F) from G[..., a, b, i, j] = int d_i f_a d_j f_b of F functions (DOF 3 a + c)."""
    tr = np.einsum("...abii->...ab", G)
    K = lam * np.swapaxes(G, -3, -2)
    K = K + mu * np.moveaxis(G, (-4, -3, -2, -1), (-4, -2, -1, -3))
    K = K + mu * tr[..., :, None, :, None] * np.eye(3)[:, None, :]
    F = G.shape[-4]
    return K.reshape(G.shape[:-4] + (3 * F, 3 * F))


def _side_integrals(subs, sown, ssg, m, h, fn, q=3):
    """Per side (0: phi < 0, 1: phi > 0) of each cut voxel: G[a, b, i, j] = int d_i f_a d_j f_b,
    int d_i f_a and the volume, for the scalar functions ``fn(xi, N, dN, owner, sign)`` -> grads."""
    lam, wq = tet_rule(q)
    G = g1 = None
    vol = np.zeros((2, m))
    for s0 in range(0, subs.shape[0], 2000):
        sl = slice(s0, s0 + 2000)
        P, ow, sg = subs[sl], sown[sl], ssg[sl]
        v = np.abs(np.linalg.det(P[:, 1:] - P[:, :1])) / 6.0 * h ** 3
        xi = np.einsum("qk,skd->sqd", lam, P)
        N, dN = q1(xi)
        g = fn(N, dN / h, ow, sg)                                       # (S, Q, F, 3)
        if G is None:
            F = g.shape[2]
            G, g1 = np.zeros((2, m, F, F, 3, 3)), np.zeros((2, m, F, 3))
        wg = (wq[None, :] * v[:, None])[..., None, None] * g
        side = (sg > 0).astype(int)
        np.add.at(G, (side, ow), np.einsum("sqai,sqbj->sabij", wg, g, optimize=True))
        np.add.at(g1, (side, ow), wg.sum(axis=1))
        np.add.at(vol, (side, ow), v)
    return G, g1, vol


def xfem_ridge_matrices(phi_c, h, lames, Es):
    """Ridge-enriched Q1 (functions [N_a, N_a psi]): (m, 48, 48), loads, affine energy."""
    m = phi_c.shape[0]
    subs, sown, ssg, *_ = cut_pieces(phi_c)

    def grads(N, dN, ow, sg):
        ph = phi_c[ow]
        psi = np.einsum("sqa,sa->sq", N, np.abs(ph)) - sg[:, None] * np.einsum("sqa,sa->sq", N, ph)
        dpsi = (np.einsum("sqad,sa->sqd", dN, np.abs(ph))
                - sg[:, None, None] * np.einsum("sqad,sa->sqd", dN, ph))
        return np.concatenate([dN, psi[..., None, None] * dN + N[..., None] * dpsi[..., None, :]],
                              axis=-2)
    G, g1, vol = _side_integrals(subs, sown, ssg, m, h, grads)
    K = _iso_K(G[0], *lames[0]) + _iso_K(G[1], *lames[1])
    loads = [np.zeros((m, 16, 3)) for _ in Es]
    for s in range(2):
        lam, mu = lames[s]
        for e, E in enumerate(Es):
            St = voigt_to_tensor(asm.isotropic_voigt(lam, mu) @ E)
            loads[e] -= np.einsum("maj,ij->mai", g1[s], St)
    return K, [f.reshape(m, 48) for f in loads], vol


def nitsche_matrices(phi_c, h, lames, youngs, Es, safety=2.0, q=3):
    """Two Q1 copies per cut voxel ([phi < 0 copy, phi > 0 copy]) glued by symmetric Nitsche:
    (m, 48, 48), loads, side volumes and the penalty (m,) [Pa / m]."""
    m = phi_c.shape[0]
    subs, sown, ssg, tris, town, tnrm = cut_pieces(phi_c)
    G, g1, vol = _side_integrals(subs, sown, ssg, m, h, lambda N, dN, ow, sg: dN, q=q)
    gbar = g1.reshape(2, m, 24) / np.maximum(vol, 1e-300)[:, :, None]    # side-mean d_c N_a
    Kb = np.stack([_iso_K(G[s], 0.0, lames[s][1])
                   + lames[s][0] * vol[s][:, None, None] * gbar[s][:, :, None] * gbar[s][:, None, :]
                   for s in range(2)])                                   # B-bar per side
    lt, wt = tri_rule(q + 1)
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]),
                                axis=1) * h ** 2
    N, dN = q1(np.einsum("qk,skd->sqd", lt, tris))
    dN = dN / h
    nq = np.broadcast_to(tnrm[:, None, :], N.shape[:2] + (3,))
    w = wt[None, :] * area[:, None]
    dn = np.einsum("sqak,sqk->sqa", dN, nq)
    Tn = []
    for s in range(2):      # traction (B-bar stress) of the 24 functions, (T, Q, 3, 24)
        lam, mu = lames[s]
        T = np.zeros(N.shape[:2] + (3, 8, 3))
        for k in range(3):
            for c in range(3):
                T[..., k, :, c] = mu * dN[..., :, k] * nq[..., c, None]
            T[..., k, :, k] += mu * dn
        T = T.reshape(N.shape[:2] + (3, 24))
        Tn.append(T + lam * nq[..., :, None] * gbar[s][town][:, None, None, :])
    kap = vol / np.asarray(youngs)[:, None]
    wts = kap / kap.sum(axis=0)
    lmax = np.zeros((2, m))
    for s in range(2):
        A = np.zeros((m, 24, 24))
        np.add.at(A, town, np.einsum("sq,sqki,sqkj->sij", w, Tn[s], Tn[s]))
        L = np.linalg.cholesky(Kb[s] + 1e-12 * np.abs(Kb[s]).max(axis=(1, 2))[:, None, None]
                               * np.eye(24))
        Li = np.linalg.inv(L)
        lmax[s] = np.linalg.eigvalsh(Li @ A @ np.swapaxes(Li, 1, 2))[:, -1]
    alpha = safety * (wts ** 2 * lmax).sum(axis=0)
    Jm = np.einsum("sqa,kc->sqkac", N, np.eye(3)).reshape(N.shape[:2] + (3, 24))
    J = np.concatenate([Jm, -Jm], axis=-1)          # [v] = v(phi < 0) - v(phi > 0)
    Tavg = np.concatenate([wts[s][town][:, None, None, None] * Tn[s] for s in range(2)], -1)
    JT = np.einsum("sq,sqki,sqkj->sij", w, J, Tavg)
    JJ = np.einsum("sq,sqki,sqkj->sij", w, J, J)
    K = np.zeros((m, 48, 48))
    np.add.at(K, town, -JT - np.swapaxes(JT, 1, 2) + alpha[town][:, None, None] * JJ)
    K[:, :24, :24] += Kb[0]
    K[:, 24:, 24:] += Kb[1]
    loads = []
    for E in Es:
        f = np.zeros((m, 48))
        tavg = 0.0
        for s in range(2):
            St = voigt_to_tensor(asm.isotropic_voigt(*lames[s]) @ E)
            f[:, 24 * s:24 * s + 24] -= np.einsum("maj,ij->mai", g1[s], St).reshape(m, 24)
            tavg = tavg + wts[s][town][:, None, None] * np.einsum("ij,sqj->sqi", St, nq)
        np.add.at(f, town, np.einsum("sq,sqki,sqk->si", w, J, tavg))
        loads.append(f)
    return K, loads, vol, alpha


# ------------------------------------------------------------------------------------------------
# the periodic cell problem with cut voxels
# ------------------------------------------------------------------------------------------------

def homogenize_cut(phi_fn, n, method, cases=(3, 4, 5), particle=FE_EL, matrix=PDMS_EL,
                   tol=1e-10, safety=2.0):
    """C_eff entries (len(cases) x len(cases), Voigt, Pa) of the periodic cell [0, 1)^3 with the
    particle where phi_fn < 0, ``method`` "nitsche" or "xfem-ridge"; also the discrete particle
    volume fraction, CG iterations and, for "nitsche", the penalty range alpha h / E_matrix."""
    h = 1.0 / n
    lames = (particle.lame_Pa, matrix.lame_Pa)
    phi, nodes = nodal_phi(phi_fn, n)
    pc = phi[nodes]
    nneg = (pc < 0).sum(axis=1)
    cut = (nneg > 0) & (nneg < 8)
    full = nneg == 8
    lam = np.where(full, lames[0][0], lames[1][0]).reshape(n, n, n)
    mu = np.where(full, lames[0][1], lames[1][1]).reshape(n, n, n)
    lam[cut.reshape(n, n, n)] = mu[cut.reshape(n, n, n)] = 0.0
    Es = [np.eye(6)[c] for c in cases]
    cvox = np.flatnonzero(cut)
    extra = {}
    if method == "nitsche":
        Ke, loads, vol, alpha = nitsche_matrices(pc[cvox], h, lames,
                                                 (particle.E_Pa, matrix.E_Pa), Es, safety)
        extra["alpha_h_over_E_matrix"] = [float(np.min(alpha) * h / matrix.E_Pa),
                                          float(np.median(alpha) * h / matrix.E_Pa),
                                          float(np.max(alpha) * h / matrix.E_Pa)]
    elif method == "xfem-ridge":
        Ke, loads, vol = xfem_ridge_matrices(pc[cvox], h, lames, Es)
    else:
        raise ValueError(method)
    xnodes = np.unique(nodes[cvox])
    xid = -np.ones(n ** 3, np.int64)
    xid[xnodes] = np.arange(xnodes.size)
    nstd, ndof = 3 * n ** 3, 3 * n ** 3 + 3 * xnodes.size
    cn = nodes[cvox]
    std = 3 * cn[:, :, None] + np.arange(3)
    ext = nstd + 3 * xid[cn][:, :, None] + np.arange(3)
    if method == "nitsche":     # a node's own phase uses its standard unknowns
        negnode = (phi[cn] < 0)[:, :, None]
        dof = np.concatenate([np.where(negnode, std, ext), np.where(negnode, ext, std)], axis=1)
    else:
        dof = np.concatenate([std, ext], axis=1)
    dof = dof.reshape(-1, 48)
    K = asm.assemble_bsr(lam, mu, h).tocsr()
    K.resize((ndof, ndof))
    K = (K + sp.coo_matrix((Ke.ravel(), (np.repeat(dof, 48, axis=1).ravel(),
                                         np.tile(dof, (1, 48)).ravel())),
                           shape=(ndof, ndof)).tocsr()).tocsr()
    F = []
    for e, c in enumerate(cases):
        f = np.zeros(ndof)
        f[:nstd] = asm.affine_load(lam, mu, h, voigt_to_tensor(np.eye(6)[c], engineering=True))
        np.add.at(f, dof.ravel(), loads[e].ravel())
        F.append(f)
    Cv = [asm.isotropic_voigt(*lm) for lm in lames]
    whole = np.where(full[~cut, None, None], Cv[0], Cv[1])
    aff = np.array([[h ** 3 * np.einsum("i,mij,j->", Ea, whole, Eb)
                     + sum(vol[s].sum() * (Ea @ Cv[s] @ Eb) for s in range(2))
                     for Eb in Es] for Ea in Es])
    keep = np.ones(ndof, bool)
    keep[:3] = False                  # pin node 0 (the callers keep it in the matrix)
    Kr = K[keep][:, keep].tocsr()
    B = np.zeros((ndof, 6))
    rb = asm.rigid_body_modes(n, h)
    B[:nstd] = rb
    if method == "nitsche":           # both copies move with a rigid motion of the cell
        B[nstd:] = rb.reshape(n ** 3, 3, 6)[xnodes].reshape(-1, 6)
    ml = pyamg.smoothed_aggregation_solver(Kr, B=B[keep], symmetry="hermitian",
                                           coarse_solver="splu", max_coarse=2000)
    W, its = [], []
    fmax = max(np.linalg.norm(f) for f in F)
    for f in F:
        w = np.zeros(ndof)
        if np.linalg.norm(f) > 1e-12 * fmax:        # a load that vanishes by symmetry
            res = []
            w[keep] = ml.solve(f[keep], tol=tol, accel="cg", maxiter=5000, residuals=res)
            if res[-1] > 10 * tol * res[0]:
                raise RuntimeError(f"CG did not converge: {res[-1] / res[0]:.1e}")
            its.append(len(res) - 1)
        else:
            its.append(0)
        W.append(w)
    C = np.array([[aff[a, b] - F[a] @ W[b] for b in range(len(cases))]
                  for a in range(len(cases))])
    phi_h = ((full.sum() * h ** 3) + vol[0].sum())
    return C, float(phi_h), its, extra


# ------------------------------------------------------------------------------------------------
# experiment 1: the tilted laminate
# ------------------------------------------------------------------------------------------------

def _cube_below(t, m):
    """Volume of {y in [0, 1]^3 : m . y <= t} for m > 0 componentwise (inclusion-exclusion)."""
    out = np.zeros_like(t)
    for v in itertools.product((0, 1), repeat=3):
        out += (-1) ** sum(v) * np.maximum(t - np.dot(m, v), 0.0) ** 3
    return out / (6.0 * m[0] * m[1] * m[2])


def laminate_fractions(n, m=LAMINATE_NORMAL, f=LAMINATE_F):
    """Exact Fe fraction per voxel (n, n, n) [k, j, i] of the periodic laminate Fe where
    (m . x / L - LAMINATE_SHIFT / n) mod 1 < f."""
    k, j, i = np.meshgrid(*(np.arange(n),) * 3, indexing="ij")
    s0 = (m[0] * i + m[1] * j + m[2] * k).astype(float)
    frac = np.zeros((n, n, n))
    for layer in range(-1, int((s0.max() + sum(m)) // n) + 2):
        lo, hi = layer * n + LAMINATE_SHIFT, (layer + f) * n + LAMINATE_SHIFT
        frac += (_cube_below(np.clip(hi - s0, 0, None), m)
                 - _cube_below(np.clip(lo - s0, 0, None), m))
    return np.clip(frac, 0.0, 1.0)


def laminate_phi(n, m=LAMINATE_NORMAL, f=LAMINATE_F):
    """Signed distance [box] to the interfaces of the laminate of :func:`laminate_fractions`
    on the n^3 grid (negative in Fe)."""
    mm = np.asarray(m, dtype=float)

    def phi(x):
        u = np.mod(x @ mm - LAMINATE_SHIFT / n, 1.0)
        inside = np.minimum(u, f - u)
        outside = np.minimum(u - f, 1.0 - u)
        return np.where(u < f, -inside, outside) / np.linalg.norm(mm)
    return phi


def laminate_errors(C):
    """Relative energy error along each eigenvector of the exact laminate, soft modes first."""
    n = np.asarray(LAMINATE_NORMAL, float) / np.linalg.norm(LAMINATE_NORMAL)
    exact = asm.laminate_voigt(asm.isotropic_voigt(*FE_EL.lame_Pa),
                               asm.isotropic_voigt(*PDMS_EL.lame_Pa),
                               np.array([LAMINATE_F]), n[None])[0]
    lam, V = np.linalg.eigh(exact)
    return [float(V[:, a] @ C @ V[:, a] / lam[a] - 1.0) for a in range(6)], lam.tolist()


def laminate_run(n, method):
    t0 = time.perf_counter()
    if method in ("composite", "laminate"):
        fr = laminate_fractions(n)
        nrm = np.asarray(LAMINATE_NORMAL, float) / np.linalg.norm(LAMINATE_NORMAL)
        z = np.zeros(0)
        mesh = VoxelMesh(n=n, box_m=1e-6, fraction=fr, owner=np.where(fr >= 0.5, 0, -1),
                         centers_m=np.zeros((0, 3)), radii_m=z, force_ptr=np.zeros(1, np.int64),
                         force_voxels=np.zeros(0, np.int64), force_weights=z,
                         resolved=np.zeros(0, bool), method=method,
                         normal=np.broadcast_to(nrm, (n, n, n, 3)).copy())
        # no particle deflation: the layers are connected sheets, not floating particles
        r = homogenize_mesh(mesh, deflate=False, solver="matrix-free", maxiter=5000)
        C, its, phi_h = r.C_eff_Pa, list(r.iterations.values()), float(fr.mean())
    else:
        C, phi_h, its, _ = homogenize_cut(laminate_phi(n), n, method, cases=range(6))
    err, _ = laminate_errors(C)
    return {"method": method, "voxels": n, "layer_spacing_voxels": n / np.sqrt(3.0),
            "phi_h": phi_h, "energy_errors_soft_to_stiff": err, "cg_iterations": its,
            "seconds": time.perf_counter() - t0}


# ------------------------------------------------------------------------------------------------
# experiment 2: one dilute sphere
# ------------------------------------------------------------------------------------------------

def sphere_run(n, offset, method="nitsche", matched=True, safety=2.0):
    """Shear coefficients (C44, C55, C66 as (G/G_m - 1)/phi) of the sphere at centre
    0.5 + offset / n."""
    t0 = time.perf_counter()
    centre = 0.5 + np.asarray(offset) / n
    radius = volume_matched_radius(centre, n) if matched else RADIUS
    C, phi_h, its, extra = homogenize_cut(sphere_fn(centre, radius), n, method, safety=safety)
    g_m = PDMS_EL.bulk_shear_Pa[1]
    c = [(C[a, a] / g_m - 1.0) / PHI for a in range(3)]
    return {"method": method, "voxels": n, "diameter_voxels": 2 * RADIUS * n,
            "offset_voxels": list(map(float, offset)), "volume_matched": matched,
            "radius_over_nominal": radius / RADIUS, "phi_h_over_phi": phi_h / PHI,
            "penalty_safety": safety, "c44_c55_c66": c, "coefficient": float(np.mean(c)),
            "error_vs_p2_limit": float(np.mean(c) / P2_LIMIT - 1.0), "cg_iterations": its,
            **extra, "seconds": time.perf_counter() - t0}


def analyse(doc):
    """Per resolution: mean error against the P2 limit over offsets; local and fitted orders."""
    rows = [r for r in doc["sphere"] if r["method"] == "nitsche" and r["volume_matched"]
            and r["penalty_safety"] == 2.0]
    table = []
    for n in sorted({r["voxels"] for r in rows}):
        rs = [r for r in rows if r["voxels"] == n]
        c = np.array([r["c44_c55_c66"] for r in rs])
        table.append({"voxels": n, "diameter_voxels": rs[0]["diameter_voxels"], "offsets": len(rs),
                      "mean_coefficient": float(c.mean()),
                      "mean_error": float(c.mean() / P2_LIMIT - 1.0),
                      "std_over_offsets_and_components": float(c.std(ddof=1) / c.mean())
                      if c.size > 1 else None})
    D = np.array([t["diameter_voxels"] for t in table])
    e = np.array([t["mean_error"] for t in table])
    out = {"table": table}
    if len(table) >= 2 and np.all(e > 0):
        out["local_orders"] = (-np.diff(np.log(e)) / np.diff(np.log(D))).tolist()
        A = np.stack([np.ones_like(D), np.log(D)], axis=1)
        coef, res, *_ = np.linalg.lstsq(A, np.log(e), rcond=None)
        out["fitted_order"] = float(-coef[1])
        if len(table) > 2:
            cov = (res[0] / (len(D) - 2)) * np.linalg.inv(A.T @ A) if res.size else None
            out["fitted_order_se"] = float(np.sqrt(cov[1, 1])) if cov is not None else None
        # Richardson at order 2 from successive resolutions: an estimate of the cell's exact
        # coefficient independent of the P2 reference
        c = np.array([t["mean_coefficient"] for t in table])
        out["richardson_order2"] = [
            {"diameters_voxels": [float(D[i]), float(D[i + 1])],
             "c_limit": float((D[i + 1] ** 2 * c[i + 1] - D[i] ** 2 * c[i])
                              / (D[i + 1] ** 2 - D[i] ** 2))} for i in range(len(D) - 1)]
        for r in out["richardson_order2"]:
            r["vs_p2_limit"] = r["c_limit"] / P2_LIMIT - 1.0
        # the same fit with the reference moved by its error estimate
        for sgn, key in ((1, "order_if_limit_plus_err"), (-1, "order_if_limit_minus_err")):
            ce = np.array([t["mean_coefficient"] for t in table]) / (P2_LIMIT + sgn * P2_ERR) - 1
            if np.all(ce > 0):
                out[key] = float(-np.polyfit(np.log(D), np.log(ce), 1)[0])
    doc["analysis"] = out
    return doc


def composite_reference():
    """Composite-voxel mean errors of dilute_rate.json (same cell, same reference)."""
    p = HERE / "dilute_rate.json"
    if not p.exists():
        return []
    d = json.loads(p.read_text())
    return [{"diameter_voxels": t["diameter_voxels"], "mean_error": t["mean_error"]}
            for t in d.get("table", [])]


def _log_axes(ax, xlabel, ylabel, title, xticks):
    import matplotlib.ticker
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=7)
    ax.grid(True, which="both", alpha=0.3)
    ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xticks(xticks)


def plot(path, doc):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.3))
    comp = doc.get("composite_dilute_rate", [])
    if comp:
        ax.plot([t["diameter_voxels"] for t in comp], [100 * abs(t["mean_error"]) for t in comp],
                "s--", color="tab:blue", label="composite voxels (dilute_rate.json), |error|")
    tab = doc["analysis"]["table"]
    D = np.array([t["diameter_voxels"] for t in tab])
    ax.plot(D, [100 * t["mean_error"] for t in tab], "o-", color="tab:red",
            label="Nitsche cut voxels (volume-matched), error")
    xr = [r for r in doc["sphere"] if r["method"] == "xfem-ridge"]
    if xr:
        ax.plot([r["diameter_voxels"] for r in xr], [100 * r["error_vs_p2_limit"] for r in xr],
                "^:", color="tab:gray", label="ridge XFEM (locks at Fe contrast), error")
    ref = 100 * P2_ERR / P2_LIMIT
    ax.axhline(ref, color="k", lw=0.8, ls=":", label=f"P2 reference uncertainty ({ref:.2f} %)")
    Dg = np.array([D.min(), D.max()])
    ax.plot(Dg, 100 * tab[-1]["mean_error"] * (Dg / D[-1]) ** -2, color="tab:red", lw=0.6,
            alpha=0.6, label="slope -2")
    _log_axes(ax, "sphere diameter [voxels]", "error of c = (G/G_m - 1)/phi vs P2 limit [%]",
              "One dilute Fe sphere in PDMS (phi 0.01)", [4, 6, 8, 10, 16, 20, 30])
    lam = doc["laminate"]
    for meth, mk, col in (("composite", "s--", "tab:blue"), ("laminate", "d--", "tab:green")):
        rs = sorted((r for r in lam if r["method"] == meth), key=lambda r: r["voxels"])
        if rs:
            bx.plot([r["layer_spacing_voxels"] for r in rs],
                    [100 * max(r["energy_errors_soft_to_stiff"][:3]) for r in rs], mk, color=col,
                    label=f"{meth} voxels")
    for meth, mk, col in (("nitsche", "o", "tab:red"), ("xfem-ridge", "^", "tab:gray")):
        rs = [r for r in lam if r["method"] == meth]
        if rs:
            bx.plot([r["layer_spacing_voxels"] for r in rs],
                    [max(100 * max(abs(x) for x in r["energy_errors_soft_to_stiff"][:3]), 1e-7)
                     for r in rs], mk, color=col, ms=9, label=f"{meth} (exact to the solver)")
    _log_axes(bx, "laminate layer spacing [voxels]", "largest soft-mode energy error [%]",
              "Fe/PDMS laminate, normal (1,1,1), Fe 50 %", [10, 20, 40])
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


FULL = {"laminate": [("composite", 18), ("composite", 36), ("composite", 72), ("laminate", 18),
                     ("laminate", 36), ("nitsche", 18), ("xfem-ridge", 18)],
        "sphere_voxels": {16: 4, 22: 4, 30: 4, 40: 4, 60: 2},
        "xfem_voxels": (16, 24), "nominal_voxels": (16, 32), "safety_voxels": 22}
QUICK = {"laminate": [("composite", 18), ("composite", 36), ("nitsche", 18)],
         "sphere_voxels": {16: 2, 22: 2}, "xfem_voxels": (16,), "nominal_voxels": (),
         "safety_voxels": None}


def run(plan):
    offsets = np.random.default_rng(SEED).random((max(plan["sphere_voxels"].values()), 3))
    doc = {"laminate": [], "sphere": []}
    for meth, n in plan["laminate"]:
        doc["laminate"].append(laminate_run(n, meth))
        print("laminate", meth, n, ["%+.2e" % x for x in doc["laminate"][-1][
            "energy_errors_soft_to_stiff"]], flush=True)
    for n, k in plan["sphere_voxels"].items():
        for o in offsets[:k]:
            doc["sphere"].append(sphere_run(n, o))
            print("sphere nitsche", n, "%+.3f %%" % (100 * doc["sphere"][-1]["error_vs_p2_limit"]),
                  flush=True)
    for n in plan["nominal_voxels"]:
        doc["sphere"].append(sphere_run(n, offsets[0], matched=False))
    if plan["safety_voxels"]:
        for sf in (1.1, 5.0):
            doc["sphere"].append(sphere_run(plan["safety_voxels"], offsets[0], safety=sf))
    for n in plan["xfem_voxels"]:
        doc["sphere"].append(sphere_run(n, offsets[0], method="xfem-ridge"))
        print("sphere xfem", n, "%+.1f %%" % (100 * doc["sphere"][-1]["error_vs_p2_limit"]),
              flush=True)
    doc["composite_dilute_rate"] = composite_reference()
    return analyse(doc)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--plot-only", action="store_true")
    ap.add_argument("--reanalyse", action="store_true",
                    help="recompute the analysis of the JSON's raw rows and redraw the figure")
    a = ap.parse_args(argv)
    out = a.out or (Path("/tmp/cut_cell_experiments_quick.json") if a.quick else JSON)
    if a.plot_only or a.reanalyse:
        doc = json.loads(out.read_text())
        if a.reanalyse:
            analyse(doc)
            out.write_text(json.dumps(doc, indent=1))
        plot(out.with_suffix(".png"), doc)
        return 0
    t0 = time.perf_counter()
    doc = run(QUICK if a.quick else FULL)
    doc["manifest"] = {
        "command": " ".join([".venv/bin/python", "results/cell/cut_cell_experiments.py"]
                            + (argv if argv is not None else sys.argv[1:])),
        "git": subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, cwd=HERE).stdout.strip(),
        "python": platform.python_version(), "seconds": time.perf_counter() - t0,
        "reference": f"curved P2 limit {P2_LIMIT} +- {P2_ERR} (dilute_rate.json)",
        "materials": "Fe 211 GPa nu 0.29 in PDMS 2 MPa nu 0.45 (micro.materials)"}
    tmp = out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(doc, indent=1))
    tmp.replace(out)
    plot(out.with_suffix(".png"), doc)
    print(json.dumps(doc["analysis"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
