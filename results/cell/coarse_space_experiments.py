"""What limits the matrix-free V-cycle's iteration count: five measured hypotheses, the numbers
behind results/cell/coarse_space_experiments.json and the section "Coarse-space experiments" of
results/cell/README.md.

RVE family and load as `mapsim bench` and multigrid_robustness.py (homogenize.bench.bench_cell.bench_rve,
6 unit strains + random particle forces, tol 1e-6); mostly the case "100 particles of 1.25 voxels
mean radius at 32^3" (rve_voxels 64, voxels 32), where solver="matrix-free" needs 45 / 82
(strain / magnetic) iterations and solver="fast" 20 / 30.

1. "rigid": coarse-grid locking. The trilinear coarse functions are cut to zero on every node of
   a voxel holding iron (so no coarse function deforms a particle), and each particle's six
   rigid modes on those nodes are added as coarse unknowns (coarse functions rigid on every
   inclusion, the classical robust coarse space for high-contrast inclusions). The coarse matrix
   [T0 Z]^T K [T0 Z] is assembled (T0^T K T0 element by element, T0^T K Z and Z^T K Z from the
   sparse K Z) and solved by pyamg smoothed aggregation ("rigid") or a sparse LU ("rigid-lu");
   "rigid-smoothed": the rigid modes smoothed by one damped Jacobi step, as smoothed
   aggregation smooths its prolongator.
2. "capped": the coarse operator built from the fine element matrices with the iron's stiffness
   capped at `cap` times the matrix's (a preconditioner of a milder problem).
3. "sweeps": 2 or 3 Gauss-Seidel sweeps per side on the fine level.
4. "method": the staircase voxels ("centre": isotropic iron and PDMS voxels only, no cut voxel)
   against the default composite voxels.
5. "nu": PDMS Poisson's ratio 0.3 / 0.45 (the default, seed) / 0.49, with iron and with particles
   of the matrix's own stiffness (a homogeneous cell: no contrast at all).
6. "sa-two-grid": the first level of smoothed aggregation in the matrix-free solver's place. A
   two-grid cycle with the same fine smoother (one 8-colour block Gauss-Seidel sweep per side,
   matrix-free) whose coarse space is the first prolongator P of `"fast"`'s hierarchy (pyamg
   smoothed aggregation of the assembled fine matrix, SolverOptions().amg, rigid-body candidates),
   solved exactly (sparse LU of P^T K P); "sa-two-grid-tentative": the same aggregates with the
   unsmoothed tentative prolongator T. Against the trilinear two-grid cycle with an exact coarse
   solve (multigrid_robustness.py, matfree_coarse = "lu") this tells whether the first coarse
   space is what makes smoothed aggregation robust, and whether its smoothing or its
   aggregates carry it.
7. "aggregate-two-grid": the same two-grid cycle with GEOMETRIC aggregates that a matrix-free
   solver could build without the fine matrix: block^3 node blocks of the grid (block 2 or 4),
   split by body (each stiff particle's nodes, the matrix's nodes) unless split=False, each
   aggregate's six rigid modes (orthonormalized per aggregate), unsmoothed; the coarse problem
   solved exactly ("lu"), by one smoothed-aggregation V-cycle ("amg") or by three ("amg3").
   Also on the hard case of multigrid_robustness.py (801 particles of 1.25 voxels mean radius
   at 64^3) and on the 64^3 bench RVE.

The experimental preconditioners live in this script (they are not part of mapsim); they take
the matrix-free solver's place after its setup (SolverOptions.preconditioner).
Run: .venv/bin/python results/cell/coarse_space_experiments.py   (~50 min from scratch)
     --out F writes the JSON elsewhere; --missing runs only the cases it does not hold yet.
"""
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

import homogenize.solvers.matfree as mf
import homogenize.cell.problem as cell
from homogenize.solvers import (BlockVCycle, SolverOptions, grid_node_coordinates,
                                rigid_body_modes, smoothed_aggregation)
from homogenize.bench.bench_cell import bench_rve
from micro.materials import PDMS

import resumable

HERE = Path(__file__).resolve().parent
JSON = HERE / "coarse_space_experiments.json"


def coarsen_truncated(field: mf.ElementField, keep: np.ndarray) -> mf.ElementField:
    """``T0^T K T0`` element by element, T0 the trilinear prolongation with the rows of the fine
    nodes ``~keep`` set to zero."""
    n = field.n
    nc = n // 2
    e = field.etype.reshape(n, n, n)
    kids = np.stack([e[cz::2, cy::2, cx::2].reshape(-1) for cx, cy, cz in mf.CORNERS], axis=1)
    k3 = keep.reshape(n, n, n)
    km = np.empty((nc ** 3, 8, 8), dtype=bool)      # (coarse voxel, child, child's corner)
    for c, (cx, cy, cz) in enumerate(mf.CORNERS):
        for a, (ax, ay, az) in enumerate(mf.CORNERS):
            km[:, c, a] = np.roll(k3, shift=(-(cz + az), -(cy + ay), -(cx + ax)),
                                  axis=(0, 1, 2))[::2, ::2, ::2].reshape(-1)
    Pc = mf.child_prolongations()
    ns = field.n_shared
    uniform = np.all(kids == kids[:, :1], axis=1) & (kids[:, 0] < ns) & km.all(axis=(1, 2))
    own = np.flatnonzero(~uniform)
    Ktab = np.empty((ns + own.size, 24, 24))
    Ktab[:ns] = np.einsum("cia,tij,cjb->tab", Pc, field.Ktab[:ns], Pc, optimize=True)
    for s in range(0, own.size, 4096):
        sl = own[s:s + 4096]
        acc = np.zeros((sl.size, 24, 24))
        for c in range(8):
            P = Pc[c][None] * np.repeat(km[sl, c, :], 3, axis=1)[:, :, None]
            acc += np.einsum("mia,mij,mjb->mab", P, field.Ktab[kids[sl, c]], P, optimize=True)
        Ktab[ns + s:ns + s + sl.size] = acc
    etype = np.where(uniform, kids[:, 0], 0).astype(np.int32)
    etype[own] = ns + np.arange(own.size, dtype=np.int32)
    return mf.ElementField(nc, etype, Ktab, ns)


class RigidInclusionTwoGrid:
    """Two-grid V-cycle: fine 8-colour Gauss-Seidel, coarse space [T0, Z] (see module docstring)."""

    def __init__(self, op, field, Z, pin, h, exact, smooth=False):
        n = field.n
        nc = n // 2
        N = n ** 3
        self.op, self.nc, self.colours = op, nc, mf.grid_colours(n)
        Z = sp.csr_matrix(Z)
        snode = np.zeros(3 * N, dtype=bool)
        snode[np.flatnonzero(np.diff(Z.indptr))] = True
        snode = snode.reshape(N, 3).any(axis=1)
        self.keep3 = np.repeat(~snode, 3).astype(float)[:, None]
        Agg = sp.csr_matrix(mf.typed_bsr(coarsen_truncated(field, ~snode)))
        d = Agg.diagonal()
        scale = d[d > 0].mean()
        # coarse nodes whose whole support lies on iron: no coarse function, unit diagonal
        Agg = Agg + sp.diags(np.where(d <= 1e-12 * scale, scale, 0.0))
        T0 = sp.diags(self.keep3[:, 0]) @ mf.prolongation_matrix(nc)
        KZ = sp.csr_matrix(mf.stiffness_times_sparse(field, Z, pin=-1))
        if smooth:
            # the rigid modes smoothed as smoothed aggregation smooths its tentative prolongator:
            # Z - 4/3 rho^-1 D^-1 K Z (rho: spectral radius of D^-1 K, power iteration), so they
            # decay into the matrix over one layer of nodes instead of stopping at the surface
            v = np.random.default_rng(0).normal(size=(op.shape[0], 1))
            for _ in range(15):
                w = np.einsum("pij,pjk->pik", op.dinv, (op @ v).reshape(-1, 3, 1)).reshape(-1, 1)
                rho = np.linalg.norm(w) / np.linalg.norm(v)
                v = w
            Dinv = sp.block_diag(list(op.dinv), format="csr")
            Z = (Z - (4.0 / 3.0 / rho) * (Dinv @ KZ)).tocsr()
            KZ = sp.csr_matrix(mf.stiffness_times_sparse(field, Z, pin=-1))
        Agp = (T0.T @ KZ).tocsr()
        A = sp.bmat([[Agg, Agp], [Agp.T, (Z.T @ KZ).tocsr()]]).tolil()
        ii, jj, kk = pin % n, (pin // n) % n, pin // (n * n)
        pc = ii // 2 + nc * (jj // 2 + nc * (kk // 2))
        for c in range(3):                  # the pinned coarse node, as the fine pin
            A[3 * pc + c, :] = 0.0
            A[:, 3 * pc + c] = 0.0
            A[3 * pc + c, 3 * pc + c] = scale
        A = A.tocsr()
        A = sp.bsr_matrix(0.5 * (A + A.T), blocksize=(3, 3))
        A.sort_indices()
        if exact:
            # a tiny shift: columns of T0 that cut to the same few nodes are linearly dependent
            lu = splu(sp.csc_matrix(A + 1e-9 * scale * sp.identity(A.shape[0])))
            self.coarse = lambda B: lu.solve(np.asarray(B))
        else:
            Bp = splu(sp.csc_matrix(Z.T @ Z)).solve(np.asarray(Z.T @ _modes(n)))
            B = np.vstack([_modes(nc), Bp])
            opts = SolverOptions().amg.replace(max_coarse=max(50, min(600, A.shape[0] // 120)))
            self.coarse = BlockVCycle(smoothed_aggregation(A, B, opts))
        self.Z, self.ZT = Z, Z.T.tocsr()
        self.ng = 3 * nc ** 3
        self.shape = op.shape
        # what cell reports of its preconditioner
        self.levels, self.coarse_n, self.field_bytes, self.interface_sweeps = [None], nc, [0], 0

    def __matmul__(self, B):
        B = np.ascontiguousarray(B, dtype=np.float64)
        one = B.ndim == 1
        B2 = B[:, None] if one else B
        k = B2.shape[1]
        X = np.zeros_like(B2)
        self.op.gauss_seidel(X, B2, list(self.colours))
        R = self.op.residual(X, B2)
        Rc = np.empty((self.ng, k))
        mf.restrict(self.nc, np.ascontiguousarray(R * self.keep3).reshape(-1, 3, k),
                    Rc.reshape(-1, 3, k))
        Xc = self.coarse(np.vstack([Rc, self.ZT @ R]))
        tmp = np.zeros_like(X)
        mf.prolong_add(self.nc, np.ascontiguousarray(Xc[:self.ng]).reshape(-1, 3, k),
                       tmp.reshape(-1, 3, k))
        X += tmp * self.keep3 + self.Z @ Xc[self.ng:]
        self.op.gauss_seidel(X, B2, list(self.colours[::-1]))
        return X[:, 0] if one else X

    __call__ = __matmul__

    def release(self):
        self.op.release()


class TwoGrid:
    """Two-grid cycle: one fine 8-colour Gauss-Seidel sweep per side (matrix-free), the coarse
    space spanned by the columns of ``P`` (3N x m), the coarse problem ``P^T K P`` solved
    exactly (``coarse="lu"``) or by one / three smoothed-aggregation V-cycles (``"amg"``,
    ``"amg3"``: SolverOptions().amg, the fine rigid-body modes restricted as candidates; a fixed
    number of V-cycles is still a symmetric linear operator). Module docstring, 6 and 7."""

    def __init__(self, op, field, pin, h, P, coarse="lu"):
        n = field.n
        self.op, self.colours = op, mf.grid_colours(n)
        K = sp.csr_matrix(mf.typed_bsr(field, pin=pin, pin_scale=op.pin_scale))
        Ac = (P.T @ K @ P).tocsr()
        del K
        if coarse == "lu":
            Ac = Ac.tocsc()
            lu = splu(Ac + 1e-12 * abs(Ac).max() * sp.identity(Ac.shape[0], format="csc"))
            self.solve = lu.solve
        else:
            Bc = np.asarray(P.T @ _modes(n))
            opts = SolverOptions().amg.replace(max_coarse=max(50, min(600, Ac.shape[0] // 120)))
            cyc = BlockVCycle(smoothed_aggregation(sp.bsr_matrix(Ac), Bc, opts))
            reps = 3 if coarse == "amg3" else 1

            def solve(B):
                X = cyc(B)
                for _ in range(reps - 1):
                    X = X + cyc(B - Ac @ X)
                return X
            self.solve = solve
        self.P, self.PT = P, P.T.tocsr()
        self.shape = op.shape
        # what cell reports of its preconditioner
        self.levels, self.coarse_n, self.field_bytes = [None], P.shape[1], [0]
        self.interface_sweeps = 0

    def __matmul__(self, B):
        B = np.ascontiguousarray(B, dtype=np.float64)
        one = B.ndim == 1
        B2 = B[:, None] if one else B
        X = np.zeros_like(B2)
        self.op.gauss_seidel(X, B2, list(self.colours))
        R = self.op.residual(X, B2)
        X += self.P @ self.solve(np.asarray(self.PT @ R))
        self.op.gauss_seidel(X, B2, list(self.colours[::-1]))
        return X[:, 0] if one else X

    __call__ = __matmul__

    def release(self):
        self.op.release()


def sa_prolongator(op, field, pin, h, tentative: bool) -> sp.csr_matrix:
    """The first prolongator of smoothed aggregation on the assembled fine matrix (pyamg,
    SolverOptions().amg as `"fast"` uses them), or its tentative (unsmoothed) one."""
    K = mf.typed_bsr(field, pin=pin, pin_scale=op.pin_scale)
    opts = SolverOptions().amg.replace(max_coarse=max(300, min(4000, K.shape[0] // 20)),
                                       keep=tentative)
    ml = smoothed_aggregation(K, _modes(field.n), opts)
    return sp.csr_matrix(ml.levels[0].T if tentative else ml.levels[0].P)


def aggregate_modes(n: int, h: float, body: np.ndarray, block: int) -> sp.csr_matrix:
    """Tentative prolongator of geometric aggregates: the fine nodes grouped by block^3 node
    blocks of the grid AND by body (each stiff particle, or the matrix: -1), each group's rigid
    modes (3 translations, 3 rotations about its centroid, scaled by the block size) made
    orthonormal per group (columns of groups too small for six independent modes dropped)."""
    N = n ** 3
    p = np.arange(N)
    i, j, k = p % n, (p // n) % n, p // (n * n)
    blk = (i // block) + (n // block) * ((j // block) + (n // block) * (k // block))
    _, agg = np.unique(np.stack([blk, body], axis=1), axis=0, return_inverse=True)
    agg = agg.reshape(-1)
    x = np.stack([i, j, k], axis=1).astype(float) * h
    order = np.argsort(agg, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(agg[order]) != 0])
    ends = np.r_[starts[1:], N]
    rows, cols, vals = [], [], []
    col = 0
    for a, (s0, s1) in enumerate(zip(starts, ends)):
        nodes = order[s0:s1]
        d = (x[nodes] - x[nodes].mean(axis=0)) / (block * h)
        m = nodes.size
        B = np.zeros((3 * m, 6))
        for c in range(3):
            B[c::3, c] = 1.0
        B[1::3, 3], B[2::3, 3] = -d[:, 2], d[:, 1]
        B[0::3, 4], B[2::3, 4] = d[:, 2], -d[:, 0]
        B[0::3, 5], B[1::3, 5] = -d[:, 1], d[:, 0]
        Q, R = np.linalg.qr(B)
        keep = np.abs(np.diag(R)) > 1e-8 * np.abs(np.diag(R)).max()
        Q = Q[:, keep]
        r3 = (3 * nodes[:, None] + np.arange(3)[None, :]).reshape(-1)
        rr, cc = np.meshgrid(r3, np.arange(Q.shape[1]) + col, indexing="ij")
        rows.append(rr.ravel()); cols.append(cc.ravel()); vals.append(Q.ravel())
        col += Q.shape[1]
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(3 * N, col))


def particle_of_node(Z: sp.spmatrix, N: int) -> np.ndarray:
    """(N,) the stiff particle each node moves with in the deflation space Z (its translation
    columns), -1 for a matrix node."""
    zc = sp.coo_matrix(Z)
    tr = zc.col % 6 < 3
    body = -np.ones(N, dtype=np.int64)
    body[zc.row[tr] // 3] = zc.col[tr] // 6
    return body


def _modes(n: int) -> np.ndarray:
    """The rigid-body modes of the periodic n^3 grid's nodes (the solvers' near-null space)."""
    return rigid_body_modes(grid_node_coordinates(n))


def capped_field(field, cap: float):
    """The element field with every element type's stiffness capped at ``cap`` times the
    softest shared type's (module docstring, 2)."""
    nrm = np.abs(field.Ktab).max(axis=(1, 2))
    s = np.minimum(1.0, cap * nrm[:field.n_shared].min() / nrm)
    return mf.ElementField(field.n, field.etype, field.Ktab * s[:, None, None], field.n_shared)


def preconditioner(case: dict, options: SolverOptions):
    """The matrix-free solver's preconditioner for ``case`` (SolverOptions.preconditioner): the
    solver's own V-cycle, or this script's in its place."""
    variant = case["variant"]

    def make(st):
        if variant in ("trilinear", "fast", "trilinear-lu"):
            return st.vcycle
        op, field = st.operator, st.field
        if variant == "capped":
            # the fine level smooths the true operator; the coarse levels are the Galerkin
            # operators of the capped field
            return mf.GeometricVCycle(
                capped_field(field, case["cap"]), pin=st.pin, pin_scale=op.pin_scale, h=st.h,
                amg_options=options.amg, fine_op=op,
                assembled_max=options.matfree_assembled_max, coarse=options.matfree_coarse,
                sweeps=options.matfree_sweeps,
                interface_sweeps=options.matfree_interface_sweeps,
                interface_halo=options.matfree_interface_halo)
        if variant in ("rigid", "rigid-lu", "rigid-smoothed"):
            Z = st.deflation_space(st.mesh.fraction > 0)          # every voxel holding iron
            return RigidInclusionTwoGrid(op, field, Z, st.pin, st.h, exact=variant == "rigid-lu",
                                         smooth=variant == "rigid-smoothed")
        if variant == "aggregate-two-grid":
            N = field.n ** 3
            body = (particle_of_node(st.deflation_space(st.mesh.fraction >= 0.5), N)
                    if case.get("split", True) else -np.ones(N, dtype=np.int64))
            P = aggregate_modes(field.n, st.h, body, case["block"])
        else:                                       # "sa-two-grid", "sa-two-grid-tentative"
            P = sa_prolongator(op, field, st.pin, st.h,
                               tentative=variant == "sa-two-grid-tentative")
        return TwoGrid(op, field, st.pin, st.h, P, coarse=case.get("coarse", "lu"))
    return make


def options_for(case: dict) -> SolverOptions:
    """The matrix-free V-cycle as when the JSON was made (sessions 6-8): no interface sweeps,
    independent CG columns (SolverOptions.block_cg, session 12), no particle patches;
    "trilinear-lu": the geometric two-grid cycle with an exact coarse solve; ``sweeps``: the fine
    Gauss-Seidel sweeps per side."""
    opts = SolverOptions(matfree_interface_sweeps=0, block_cg="independent",
                         patch_shell_voxels=None,
                         matfree_coarse="lu" if case["variant"] == "trilinear-lu" else "amg",
                         matfree_sweeps=case.get("sweeps", 1))
    return opts.replace(preconditioner=preconditioner(case, opts))


def run(case: dict) -> dict:
    rve = bench_rve(case["rve_voxels"], 1)
    forces = np.random.default_rng(2).normal(size=(rve.n, 3)) * 1e-15
    kw = dict(matrix_nu=case.get("nu", PDMS.nu), method=case.get("method", "composite"))
    if case.get("homogeneous"):
        kw.update(particle_E_Pa=PDMS.E_Pa, particle_nu=kw["matrix_nu"])
    t0 = time.perf_counter()
    # tol_magnetic: every column at 1e-6, as when the JSON was made (session 8)
    r = cell.homogenize_rve(rve, case["voxels"], forces_N=forces, solver=case["solver"],
                            tol_magnetic=1e-6, options=options_for(case), **kw)
    sec = time.perf_counter() - t0
    it = r.iterations
    return dict(case, n_particles=int(rve.n), iterations=it,
                max_strain_iterations=max(v for k, v in it.items() if k != "magnetic"),
                magnetic_iterations=it["magnetic"], seconds=sec, E_eff_Pa=r.E_eff_Pa)


RESULT = ("n_particles", "iterations", "max_strain_iterations", "magnetic_iterations", "seconds",
          "E_eff_Pa")


def plan() -> list[dict]:
    base = dict(rve_voxels=64, voxels=32, solver="matrix-free", variant="trilinear")
    out = [base, dict(base, solver="fast", variant="fast"),
           dict(base, variant="rigid"), dict(base, variant="rigid-lu"),
           dict(base, variant="rigid-smoothed"),
           dict(base, variant="capped", cap=1e3), dict(base, variant="capped", cap=30.0),
           dict(base, sweeps=2), dict(base, sweeps=3),
           dict(base, rve_voxels=64, voxels=64, sweeps=1),
           dict(base, rve_voxels=64, voxels=64, sweeps=2)]
    for nu in (0.3, 0.49):
        out += [dict(base, nu=nu), dict(base, nu=nu, solver="fast", variant="fast"),
                dict(base, nu=nu, variant="rigid")]
    for nu in (0.3, 0.45, 0.49):
        out += [dict(base, nu=nu, homogeneous=True),
                dict(base, nu=nu, homogeneous=True, solver="fast", variant="fast")]
    # the staircase voxels (no cut voxels: isotropic iron / PDMS only)
    out += [dict(base, method="centre"), dict(base, method="centre", solver="fast", variant="fast")]
    # the first level of smoothed aggregation as the coarse space of a two-grid cycle
    out += [dict(base, variant="sa-two-grid"), dict(base, variant="sa-two-grid-tentative"),
            dict(base, variant="trilinear-lu")]
    out += [dict(base, variant="aggregate-two-grid", block=b) for b in (2, 4)]
    out += [dict(base, variant="aggregate-two-grid", block=2, split=False),
            dict(base, variant="aggregate-two-grid", block=2, coarse="amg"),
            dict(base, variant="aggregate-two-grid", block=4, coarse="amg")]
    # the hard case of multigrid_robustness.py: 801 particles of 1.25 voxels mean radius at 64^3
    hard = dict(base, rve_voxels=128, voxels=64)
    out += [dict(hard, variant="aggregate-two-grid", block=b, coarse="amg") for b in (2, 4)]
    out += [dict(base, variant="aggregate-two-grid", block=2, coarse="amg3"),
            dict(hard, variant="aggregate-two-grid", block=2, coarse="amg3")]
    # the 64^3 bench RVE (100 particles of ~2.5 voxels mean radius): matrix-free 42 / 69
    out += [dict(base, rve_voxels=64, voxels=64, variant="aggregate-two-grid", block=2,
                 coarse="amg")]
    return out


def main() -> None:
    out, rows = resumable.parse(__doc__, JSON)
    for case in plan():
        if any(all(r.get(k) == v for k, v in case.items()) and set(case) == set(r) - set(RESULT)
               for r in rows):
            continue
        rows.append(run(case))
        print({k: rows[-1][k] for k in ("variant", "solver", "voxels", "nu", "homogeneous", "method",
                                        "cap", "sweeps", "max_strain_iterations",
                                        "magnetic_iterations", "seconds") if k in rows[-1]},
              flush=True)
        resumable.write(out, rows, "results/cell/coarse_space_experiments.py",
                         "iterations of the deflated block CG to relative residual 1e-6 (max over "
                         "the six strains / the magnetic column); seconds: wall time, not a "
                         "benchmark")


if __name__ == "__main__":
    main()
