"""Benchmarks of the macro solvers (``mapsim bench --only macro``), ratios in the same run.

* ``macro.amg_pcg``: smoothed-aggregation AMG + CG against the direct sparse solve (SuperLU) on
  a P2 cantilever; ratio = direct seconds / AMG seconds.
* ``macro.neo_hookean_tangent``: the vectorised total-Lagrangian assembly against the same
  tangent assembled through scikit-fem forms; ratio = form seconds / vectorised seconds.
"""
from __future__ import annotations

import time

import numpy as np
from homogenize.macro.cantilever import Strip, _mesh, solve_cantilever
from homogenize.macro.fem import Material, _NeoHookeanAssembler, _skfem_neo_hookean, vector_basis

__all__ = ["bench_records"]


def _timed(fn, repeat=1):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def bench_records(quick: bool) -> list[dict]:

    mat = Material()
    strip = Strip(0.0191, 5e-3, 1e-3)
    recs = []
    k = 3 if quick else 5
    div = (7 * k, k, k)
    t_amg, amg = _timed(lambda: solve_cantilever(strip, mat, 4e4, divisions=div,
                                                 solver="amg-pcg"))
    t_dir, ref = _timed(lambda: solve_cantilever(strip, mat, 4e4, divisions=div,
                                                 solver="direct"))
    recs.append({"name": "macro.amg_pcg", "n": amg.n_dof, "seconds": t_amg,
                 "reference": "scipy spsolve (SuperLU)", "reference_seconds": t_dir,
                 "ratio": t_dir / t_amg, "max_rel_error": abs(amg.tip_m / ref.tip_m - 1),
                 "iterations": amg.iterations})

    div = (7, 1, 1) if quick else (14, 2, 2)
    basis = vector_basis(_mesh(strip, div, half=True), 2)
    lam, mu = mat.lame_Pa
    rng = np.random.default_rng(0)
    u = 1e-5 * rng.normal(size=basis.N)
    asmb = _NeoHookeanAssembler(basis, lam, mu, np.zeros(3))
    t_vec, (r1, K1) = _timed(lambda: asmb.internal(u), repeat=3)
    t_ref, (r0, K0) = _timed(lambda: _skfem_neo_hookean(basis, u, lam, mu))
    err = max(abs(K1 - K0).max() / abs(K0).max(), np.abs(r1 - r0).max() / np.abs(r0).max())
    recs.append({"name": "macro.neo_hookean_tangent", "n": int(basis.N), "seconds": t_vec,
                 "reference": "scikit-fem BilinearForm/LinearForm", "reference_seconds": t_ref,
                 "ratio": t_ref / t_vec, "max_rel_error": float(err)})
    return recs
