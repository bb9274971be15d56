"""Every numba kernel of ``micro``, and nothing else.

Rules (STYLE.md): contiguous float64 arrays in, caller-allocated output, no defaults, short;
``cache=True``; no ``fastmath`` in physics kernels. Each kernel has a test against a plain-numpy
reference on a small input. Python wrappers (in particles.py, dipoles.py) check shapes and
units and allocate.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from micro.common.jit import parallel_and_serial

# ---------------------------------------------------------------------------------------------
# Placement (cell lists, overlap tests) -- owned by particles.py
# ---------------------------------------------------------------------------------------------
# A cell list is a linked list per cell: ``head[c]`` is the last particle inserted in cell c
# (-1: empty), ``nxt[i]`` the particle inserted before i in the same cell. Cells are cubes of
# edge >= the largest contact distance 2 r_max + gap, so every possible overlap partner lies in
# the 27 cells around a particle's cell (all cells when there are fewer than 3 per edge).
# Separations use the minimum image d - L rint(d / L): if the nearest image does not overlap,
# no image does, whatever the box size.


@nb.njit(cache=True)
def placement_cell_of(p, box, ncell):
    """Flat index of the cell holding position p (3,) in a periodic box cut in ncell^3 cells."""
    c = 0
    for k in range(3):
        q = int(np.floor(p[k] / box * ncell))
        q = q % ncell
        c = c * ncell + q
    return c


@nb.njit(cache=True)
def placement_overlaps(p, r, gap, centers, radii, head, nxt, box, ncell):
    """True if a sphere (p, r) comes closer than ``gap`` to any sphere in the cell list."""
    ci = placement_cell_of(p, box, ncell)
    cz = ci % ncell
    cy = (ci // ncell) % ncell
    cx = ci // (ncell * ncell)
    span = 1 if ncell >= 3 else 0
    lo = -1 if ncell >= 3 else 0
    hi = 1 if ncell >= 3 else ncell - 1
    for ax in range(lo, hi + 1):
        for ay in range(lo, hi + 1):
            for az in range(lo, hi + 1):
                if span == 1:
                    c = (((cx + ax) % ncell) * ncell + (cy + ay) % ncell) * ncell \
                        + (cz + az) % ncell
                else:
                    c = (ax * ncell + ay) * ncell + az
                j = head[c]
                while j >= 0:
                    s2 = 0.0
                    for k in range(3):
                        d = centers[j, k] - p[k]
                        d -= box * np.rint(d / box)
                        s2 += d * d
                    lim = r + radii[j] + gap
                    if s2 < lim * lim:
                        return True
                    j = nxt[j]
    return False


@nb.njit(cache=True)
def placement_rsa_bodies(offsets, radii, body_start, candidates, gap, box, ncell, head, nxt,
                         centers, state, max_attempts):
    """Random sequential addition of rigid bodies of spheres, consuming a stream of candidates.

    Body b is made of spheres ``body_start[b] <= i < body_start[b+1]`` with centres
    ``candidate + offsets[i]`` (wrapped). Candidates (M, 3) are tried in order; a body is
    accepted when none of its spheres comes closer than ``gap`` to a sphere already placed.
    ``state`` (int64, 3) = [next body, failed attempts on it, total attempts] is updated in
    place so that the caller can continue with a new batch of candidates.
    Returns 0 when all bodies are placed, 1 when the candidates ran out, 2 when a body failed
    ``max_attempts`` times in a row.
    """
    nbody = body_start.shape[0] - 1
    p = np.empty(3)
    for m in range(candidates.shape[0]):
        b = state[0]
        if b >= nbody:
            return 0
        if state[1] >= max_attempts:
            return 2
        state[1] += 1
        state[2] += 1
        ok = True
        for i in range(body_start[b], body_start[b + 1]):
            for k in range(3):
                p[k] = (candidates[m, k] + offsets[i, k]) % box
            if placement_overlaps(p, radii[i], gap, centers, radii, head, nxt, box, ncell):
                ok = False
                break
        if ok:
            for i in range(body_start[b], body_start[b + 1]):
                for k in range(3):
                    centers[i, k] = (candidates[m, k] + offsets[i, k]) % box
                c = placement_cell_of(centers[i], box, ncell)
                nxt[i] = head[c]
                head[c] = i
            state[0] = b + 1
            state[1] = 0
    if state[0] >= nbody:
        return 0
    return 2 if state[1] >= max_attempts else 1


@nb.njit(cache=True)
def placement_build_cells(centers, box, ncell, head, nxt):
    """Fill the cell list ``head`` (ncell^3,) / ``nxt`` (N,) with all particles of ``centers``."""
    head[:] = -1
    for i in range(centers.shape[0]):
        c = placement_cell_of(centers[i], box, ncell)
        nxt[i] = head[c]
        head[c] = i


@nb.njit(cache=True)
def placement_relax_step(centers, radii, gap, push_scale, box, ncell, head, nxt, disp):
    """Overlap-removal displacements: every pair closer than its contact distance
    a = r_i + r_j + gap moves each partner away along the centre line by half of
    (a * push_scale - distance), so that alone it would end slightly beyond contact.
    Writes disp (N, 3); returns the number of overlapping pairs (each counted once).
    """
    count = 0
    p = np.empty(3)
    d = np.empty(3)
    for i in range(centers.shape[0]):
        disp[i, 0] = 0.0
        disp[i, 1] = 0.0
        disp[i, 2] = 0.0
        for k in range(3):
            p[k] = centers[i, k]
        ci = placement_cell_of(p, box, ncell)
        cz = ci % ncell
        cy = (ci // ncell) % ncell
        cx = ci // (ncell * ncell)
        lo = -1 if ncell >= 3 else 0
        hi = 1 if ncell >= 3 else ncell - 1
        for ax in range(lo, hi + 1):
            for ay in range(lo, hi + 1):
                for az in range(lo, hi + 1):
                    if ncell >= 3:
                        c = (((cx + ax) % ncell) * ncell + (cy + ay) % ncell) * ncell \
                            + (cz + az) % ncell
                    else:
                        c = (ax * ncell + ay) * ncell + az
                    j = head[c]
                    while j >= 0:
                        if j != i:
                            s2 = 0.0
                            for k in range(3):
                                d[k] = p[k] - centers[j, k]
                                d[k] -= box * np.rint(d[k] / box)
                                s2 += d[k] * d[k]
                            lim = radii[i] + radii[j] + gap
                            if s2 < lim * lim:
                                dist = np.sqrt(s2)
                                if i < j:
                                    count += 1
                                if dist > 0.0:
                                    f = 0.5 * (lim * push_scale - dist) / dist
                                    for k in range(3):
                                        disp[i, k] += f * d[k]
                                else:     # coincident centres: split along x by index order
                                    disp[i, 0] += 0.5 * lim if i < j else -0.5 * lim
                        j = nxt[j]
    return count

# ---------------------------------------------------------------------------------------------
# Dipoles (direct sums, Ewald real space, forces) -- owned by dipoles.py
# ---------------------------------------------------------------------------------------------

# Conventions: fields are returned WITHOUT the 1/(4 pi) of H = (3 r (m.r)/r^5 - m/r^3) / (4 pi)
# and forces without mu0/(4 pi); the Python wrappers in dipoles.py apply them. Ewald kernels
# work in box units (cube of edge 1, centres in [0, 1)). ``B1, B2, B3`` are the Ewald screened
# radial functions B_l(r) = [(2l-1) B_{l-1} + (2 a^2)^l e^{-a^2 r^2} / (a sqrt(pi))] / r^2,
# B_0 = erfc(a r) / r, which tend to (2l-1)!! / r^(2l+1) for a -> 0 (bare dipole sums).


def _dipole_field_direct_impl(src, mom, obs, out):
    """Bare dipole field of every source at every observer, ``src, mom (3, Ns)``, ``obs, out
    (3, No)`` (structure of arrays); coincident points skipped.

    Vectorisation without fastmath: observers are taken in blocks of 256 copied into local
    buffers, and the innermost loop runs over the observers of a block with one source held in
    registers. Each lane owns one observer's accumulator, so no cross-lane reduction (which
    would need reassociation) is required, and the local buffers cannot alias the arguments,
    so LLVM emits packed IEEE vsubpd/vmulpd/vdivpd/vsqrtpd without runtime alias checks (with
    the accumulators in ``out`` directly it did not vectorise: 1.3e8 vs 5.8e8 pairs/s). The sum
    over sources runs in the same order for every observer whatever the block/thread layout:
    results are bitwise independent of the number of threads.
    """
    ns = src.shape[1]
    no = obs.shape[1]
    blk = 256
    nblk = (no + blk - 1) // blk
    for b in nb.prange(nblk):
        i0 = b * blk
        nbk = min(blk, no - i0)
        bx = np.empty(blk)
        by = np.empty(blk)
        bz = np.empty(blk)
        ax = np.zeros(blk)
        ay = np.zeros(blk)
        az = np.zeros(blk)
        for i in range(nbk):
            bx[i] = obs[0, i0 + i]
            by[i] = obs[1, i0 + i]
            bz[i] = obs[2, i0 + i]
        for j in range(ns):
            sx, sy, sz = src[0, j], src[1, j], src[2, j]
            mx, my, mz = mom[0, j], mom[1, j], mom[2, j]
            for i in range(nbk):
                dx = bx[i] - sx
                dy = by[i] - sy
                dz = bz[i] - sz
                r2 = dx * dx + dy * dy + dz * dz
                ok = r2 > 0.0
                ir2 = 1.0 / (r2 if ok else 1.0)
                ir3 = ir2 * math.sqrt(ir2) if ok else 0.0
                t = 3.0 * (mx * dx + my * dy + mz * dz) * ir2
                ax[i] += (t * dx - mx) * ir3
                ay[i] += (t * dy - my) * ir3
                az[i] += (t * dz - mz) * ir3
        for i in range(nbk):
            out[0, i0 + i] = ax[i]
            out[1, i0 + i] = ay[i]
            out[2, i0 + i] = az[i]


dipole_field_direct_par, dipole_field_direct = parallel_and_serial(_dipole_field_direct_impl)


@nb.njit(cache=True)
def ewald_b123(r, alpha):
    """Screened radial functions (B1, B2, B3) at distance r > 0 (box units)."""
    a2 = alpha * alpha
    c = 2.0 * alpha / math.sqrt(math.pi) * math.exp(-a2 * r * r)
    ir2 = 1.0 / (r * r)
    b0 = math.erfc(alpha * r) / r
    b1 = (b0 + c) * ir2
    b2 = (3.0 * b1 + 2.0 * a2 * c) * ir2
    b3 = (5.0 * b2 + 4.0 * a2 * a2 * c) * ir2
    return b1, b2, b3


@nb.njit(cache=True)
def ewald_cell_index(p, ncell):
    """Cell index along one axis of a coordinate p in [0, 1)."""
    c = int(p * ncell)
    return min(max(c, 0), ncell - 1)


def _ewald_real_impl(pos, mom, targets, order, cell_start, ncell, noff, alpha, rc, want_force,
                     out_h, out_f, out_vir):
    """Real-space Ewald part for the particles i = targets[t] over all j and images within rc
    (results in row t of the outputs).

    ``order``/``cell_start``: particles sorted by cell (cell c holds order[cell_start[c]:
    cell_start[c+1]]), ``ncell`` cells per edge; ``noff`` >= rc * ncell neighbour cells are
    visited per direction, wrapping (with the image shift) as often as needed, so any rc works.
    ``out_h`` (N,3): field sum B2 (m_j.r) r - B1 m_j. With ``want_force``: ``out_f`` (N,3)
    force on i and ``out_vir`` (N,9) half of sum_j r (x) F (row-major), without mu0/(4 pi).
    """
    rc2 = rc * rc
    for ti in nb.prange(targets.shape[0]):
        i = targets[ti]
        xi, yi, zi = pos[i, 0], pos[i, 1], pos[i, 2]
        mix, miy, miz = mom[i, 0], mom[i, 1], mom[i, 2]
        cx = ewald_cell_index(xi, ncell)
        cy = ewald_cell_index(yi, ncell)
        cz = ewald_cell_index(zi, ncell)
        # scalar accumulators (no per-particle heap arrays inside the parallel loop)
        hx = hy = hz = 0.0
        fx = fy = fz = 0.0
        vxx = vxy = vxz = vyx = vyy = vyz = vzx = vzy = vzz = 0.0
        for ox in range(-noff, noff + 1):
            gx = cx + ox
            sx = gx // ncell
            gx -= sx * ncell
            for oy in range(-noff, noff + 1):
                gy = cy + oy
                sy = gy // ncell
                gy -= sy * ncell
                for oz in range(-noff, noff + 1):
                    gz = cz + oz
                    sz = gz // ncell
                    gz -= sz * ncell
                    c = (gx * ncell + gy) * ncell + gz
                    for t in range(cell_start[c], cell_start[c + 1]):
                        j = order[t]
                        dx = xi - pos[j, 0] - sx
                        dy = yi - pos[j, 1] - sy
                        dz = zi - pos[j, 2] - sz
                        r2 = dx * dx + dy * dy + dz * dz
                        if r2 >= rc2 or r2 == 0.0:
                            continue
                        b1, b2, b3 = ewald_b123(math.sqrt(r2), alpha)
                        mjx, mjy, mjz = mom[j, 0], mom[j, 1], mom[j, 2]
                        mjr = mjx * dx + mjy * dy + mjz * dz
                        hx += b2 * mjr * dx - b1 * mjx
                        hy += b2 * mjr * dy - b1 * mjy
                        hz += b2 * mjr * dz - b1 * mjz
                        if want_force:
                            mir = mix * dx + miy * dy + miz * dz
                            mm = mix * mjx + miy * mjy + miz * mjz
                            g = b2 * mm - b3 * mir * mjr
                            px = g * dx + b2 * (mjr * mix + mir * mjx)
                            py = g * dy + b2 * (mjr * miy + mir * mjy)
                            pz = g * dz + b2 * (mjr * miz + mir * mjz)
                            fx += px
                            fy += py
                            fz += pz
                            # half of r (x) F, row-major [b, a] = d_b p_a
                            vxx += 0.5 * dx * px
                            vxy += 0.5 * dx * py
                            vxz += 0.5 * dx * pz
                            vyx += 0.5 * dy * px
                            vyy += 0.5 * dy * py
                            vyz += 0.5 * dy * pz
                            vzx += 0.5 * dz * px
                            vzy += 0.5 * dz * py
                            vzz += 0.5 * dz * pz
        out_h[ti, 0] = hx
        out_h[ti, 1] = hy
        out_h[ti, 2] = hz
        if want_force:
            out_f[ti, 0] = fx
            out_f[ti, 1] = fy
            out_f[ti, 2] = fz
            out_vir[ti, 0] = vxx
            out_vir[ti, 1] = vxy
            out_vir[ti, 2] = vxz
            out_vir[ti, 3] = vyx
            out_vir[ti, 4] = vyy
            out_vir[ti, 5] = vyz
            out_vir[ti, 6] = vzx
            out_vir[ti, 7] = vzy
            out_vir[ti, 8] = vzz


ewald_real = nb.njit(cache=True, parallel=True)(_ewald_real_impl)


@nb.njit(cache=True, parallel=True)
def ewald_structure_factor(pos, mom, kvec, out):
    """Vector structure factor t(k) = sum_j m_j exp(-i k.x_j): ``out`` (K, 6) = (Re t, Im t)."""
    nk = kvec.shape[0]
    n = pos.shape[0]
    for q in nb.prange(nk):
        kx, ky, kz = kvec[q, 0], kvec[q, 1], kvec[q, 2]
        a = np.zeros(6)
        for j in range(n):
            ph = kx * pos[j, 0] + ky * pos[j, 1] + kz * pos[j, 2]
            c = math.cos(ph)
            s = math.sin(ph)
            for d in range(3):
                a[d] += mom[j, d] * c
                a[3 + d] -= mom[j, d] * s
        for d in range(6):
            out[q, d] = a[d]


@nb.njit(cache=True, parallel=True)
def ewald_recip_gather(pos, mom, kvec, coef, out_h, out_f):
    """Per particle i: ``out_h`` = sum_k k Re[c_k e^{i k.x_i}], ``out_f`` = sum_k (m_i.k) k
    Im[c_k e^{i k.x_i}], with ``coef`` (K, 2) = (Re c_k, Im c_k)."""
    n = pos.shape[0]
    nk = kvec.shape[0]
    for i in nb.prange(n):
        hx = hy = hz = 0.0
        fx = fy = fz = 0.0
        for q in range(nk):
            kx, ky, kz = kvec[q, 0], kvec[q, 1], kvec[q, 2]
            ph = kx * pos[i, 0] + ky * pos[i, 1] + kz * pos[i, 2]
            c = math.cos(ph)
            s = math.sin(ph)
            re = coef[q, 0] * c - coef[q, 1] * s
            im = coef[q, 0] * s + coef[q, 1] * c
            hx += kx * re
            hy += ky * re
            hz += kz * re
            mk = (mom[i, 0] * kx + mom[i, 1] * ky + mom[i, 2] * kz) * im
            fx += kx * mk
            fy += ky * mk
            fz += kz * mk
        out_h[i, 0] = hx
        out_h[i, 1] = hy
        out_h[i, 2] = hz
        out_f[i, 0] = fx
        out_f[i, 1] = fy
        out_f[i, 2] = fz


@nb.njit(cache=True)
def pme_bspline(frac, p, w):
    """Cardinal B-spline weights of order p: w[q] = M_p(frac + q), q = 0..p-1, frac in [0,1).

    Grid point floor(u) - q receives weight w[q] for a particle at grid coordinate u.
    """
    for q in range(p):
        w[q] = 0.0
    w[0] = frac
    w[1] = 1.0 - frac
    # raise the order by the recursion M_n(x) = [x M_{n-1}(x) + (n - x) M_{n-1}(x - 1)]/(n-1),
    # evaluated at x = frac + q from the highest q down so w[q-1] is still of order n-1.
    for n in range(3, p + 1):
        for q in range(n - 1, -1, -1):
            x = frac + q
            here = w[q] if q < n - 1 else 0.0
            below = w[q - 1] if q > 0 else 0.0
            w[q] = (x * here + (n - x) * below) / (n - 1)
    return w


@nb.njit(cache=True)
def pme_stencil(g, p, kk, w, idx):
    """B-spline weights ``w`` (p,) and wrapped grid indices ``idx`` (p,) along one axis for a
    particle at grid coordinate g in [0, K)."""
    f = math.floor(g)
    pme_bspline(g - f, p, w)
    i0 = int(f)
    for q in range(p):
        j = i0 - q
        idx[q] = j + kk if j < 0 else (j - kk if j >= kk else j)


@nb.njit(cache=True, parallel=True)
def zero_planes(a):
    """``a[...] = 0`` on all threads, plane by plane along the first axis (the PME spread grid,
    reused between field evaluations: zeroing it in place keeps its pages resident, where a new
    ``np.zeros`` grid is mapped afresh and page-faulted in at first touch every evaluation)."""
    for i in nb.prange(a.shape[0]):
        a[i] = 0.0


@nb.njit(cache=True, parallel=True)
def pme_spread(gpos, val, p, order, slab_start, work, iwork, row, out):
    """Spread per-particle values ``val`` (N, C) onto ``out`` (K, K, K, C) (component last,
    caller-zeroed) with order-p B-splines; ``gpos`` (N, 3) are grid coordinates in [0, K).

    Race-free in parallel: the particles ``order[slab_start[s]:slab_start[s+1]]`` have
    floor(gpos_x) in x-slab s of at least p grid planes; a particle writes planes
    floor(u) - p + 1 .. floor(u), so slabs s and s + 2 never touch the same plane. With an even
    number of slabs (or one), even slabs run in parallel, then odd ones: every grid point
    receives its contributions in a fixed order whatever the number of threads.
    ``work`` (S, 3, p), ``row`` (S, >= C) float64 and ``iwork`` (S, 3, p) int64 are scratch,
    S >= slab pairs (a grid point's C values are contiguous; one particle's C values are held
    in ``row``: 1.7x faster than reading ``val`` in the innermost loop)."""
    nslab = slab_start.shape[0] - 1
    npair = (nslab + 1) // 2
    nc = val.shape[1]
    kk = out.shape[0]
    for colour in range(2):
        for h in nb.prange(npair):
            s = 2 * h + colour
            if s >= nslab:
                continue
            wx, wy, wz = work[h, 0], work[h, 1], work[h, 2]
            ix, iy, iz = iwork[h, 0], iwork[h, 1], iwork[h, 2]
            v = row[h]
            for t in range(slab_start[s], slab_start[s + 1]):
                i = order[t]
                pme_stencil(gpos[i, 0], p, kk, wx, ix)
                pme_stencil(gpos[i, 1], p, kk, wy, iy)
                pme_stencil(gpos[i, 2], p, kk, wz, iz)
                if nc == 3:
                    # the field's three components in registers: 1.5x faster than the loop
                    # over d below (same operations in the same order: the same numbers)
                    v0, v1, v2 = val[i, 0], val[i, 1], val[i, 2]
                    for a in range(p):
                        xa = ix[a]
                        for b in range(p):
                            wab = wx[a] * wy[b]
                            yb = iy[b]
                            for c in range(p):
                                w = wab * wz[c]
                                zc = iz[c]
                                out[xa, yb, zc, 0] += w * v0
                                out[xa, yb, zc, 1] += w * v1
                                out[xa, yb, zc, 2] += w * v2
                    continue
                for d in range(nc):
                    v[d] = val[i, d]
                for a in range(p):
                    for b in range(p):
                        wab = wx[a] * wy[b]
                        for c in range(p):
                            w = wab * wz[c]
                            o = out[ix[a], iy[b], iz[c]]
                            for d in range(nc):
                                o[d] += w * v[d]


@nb.njit(cache=True, parallel=True)
def pme_gather(gpos, grid, p, work, iwork, out):
    """Interpolate ``grid`` (K, K, K, C) (component last) at grid coordinates ``gpos`` (N, 3)
    with order-p B-splines into ``out`` (N, C) (the transpose of :func:`pme_spread`).
    ``work`` (S, 3, p) float64 and ``iwork`` (S, 3, p) int64: scratch of S chunks of particles
    (each particle's sum runs in the same order whatever S or the thread count). One component
    at a time, its sum in a register: the stencil's p^3 grid points stay in the L1 cache
    between the components, and the sums no longer go through memory (with all C sums in a
    scratch row it was 1.4x slower for C = 3 and C = 9; the same numbers)."""
    n = gpos.shape[0]
    nc = grid.shape[3]
    kk = grid.shape[0]
    nchunk = work.shape[0]
    for ch in nb.prange(nchunk):
        wx, wy, wz = work[ch, 0], work[ch, 1], work[ch, 2]
        ix, iy, iz = iwork[ch, 0], iwork[ch, 1], iwork[ch, 2]
        for i in range(ch * n // nchunk, (ch + 1) * n // nchunk):
            pme_stencil(gpos[i, 0], p, kk, wx, ix)
            pme_stencil(gpos[i, 1], p, kk, wy, iy)
            pme_stencil(gpos[i, 2], p, kk, wz, iz)
            for d in range(nc):
                acc = 0.0
                for a in range(p):
                    xa = ix[a]
                    for b in range(p):
                        wab = wx[a] * wy[b]
                        yb = iy[b]
                        for c in range(p):
                            acc += wab * wz[c] * grid[xa, yb, iz[c], d]
                out[i, d] = acc


@nb.njit(cache=True, parallel=True)
def pme_influence(qh, kv, kvz, g, scale, out):
    """k-space step of dipolar PME: ``out[..., a] = -scale g(k) k_a (k . qh(k))`` for the rfft
    grids ``qh`` (K, K, K/2+1, 3) (complex, component last); ``kv`` (K,) and ``kvz`` (K/2+1,)
    are the wavenumbers. ``out`` may be ``qh`` itself (each point's three values are read
    before they are written)."""
    kk = qh.shape[0]
    kz = qh.shape[2]
    for a in nb.prange(kk):
        for b in range(kk):
            for c in range(kz):
                s = kv[a] * qh[a, b, c, 0] + kv[b] * qh[a, b, c, 1] + kvz[c] * qh[a, b, c, 2]
                t = -scale * g[a, b, c] * s
                out[a, b, c, 0] = kv[a] * t
                out[a, b, c, 1] = kv[b] * t
                out[a, b, c, 2] = kvz[c] * t


@nb.njit(cache=True, parallel=True)
def pme_influence_grad(qh, kv, kvz, g, wz, scale, inv4a2, out, acc):
    """k-space step of dipolar PME with forces, energy and virial, one pass over the rfft grid.

    ``out[..., 0:3]`` = field ``k_a t`` with ``t = -scale g(k) (k . qh)``; ``out[..., 3:9]`` =
    its gradient ``i k_a k_b t`` for (a, b) = xx, yy, zz, xy, xz, yz (the field is curl-free, so
    the gradient is symmetric: 6 grids, not 9). ``acc`` (K, 10): per x-plane partial sums (added
    in a fixed order by the caller) of the energy ``(1/2) sum wz g |s|^2`` (column 0) and of
    ``P_ab = sum wz g [(1/k^2 + inv4a2) |s|^2 k_a k_b - Re(conj(s) k_a qh_b)]`` (columns 1..9,
    row-major), with ``s = k . qh`` and ``wz`` (K/2+1,) the half-space weights."""
    kk = qh.shape[0]
    nz = qh.shape[2]
    for a in nb.prange(kk):
        for q in range(10):
            acc[a, q] = 0.0
        for b in range(kk):
            for c in range(nz):
                k0, k1, k2 = kv[a], kv[b], kvz[c]
                q0, q1, q2 = qh[a, b, c, 0], qh[a, b, c, 1], qh[a, b, c, 2]
                s = k0 * q0 + k1 * q1 + k2 * q2
                gk = g[a, b, c]
                t = -scale * gk * s
                it = 1j * t
                out[a, b, c, 0] = k0 * t
                out[a, b, c, 1] = k1 * t
                out[a, b, c, 2] = k2 * t
                out[a, b, c, 3] = k0 * k0 * it
                out[a, b, c, 4] = k1 * k1 * it
                out[a, b, c, 5] = k2 * k2 * it
                out[a, b, c, 6] = k0 * k1 * it
                out[a, b, c, 7] = k0 * k2 * it
                out[a, b, c, 8] = k1 * k2 * it
                if gk == 0.0:
                    continue
                wg = wz[c] * gk
                ss = s.real * s.real + s.imag * s.imag
                acc[a, 0] += 0.5 * wg * ss
                w = wg * (1.0 / (k0 * k0 + k1 * k1 + k2 * k2) + inv4a2) * ss
                ks = (k0, k1, k2)
                qs = (q0, q1, q2)
                for x in range(3):
                    for y in range(3):
                        cq = s.real * qs[y].real + s.imag * qs[y].imag    # Re(conj(s) q_y)
                        acc[a, 1 + 3 * x + y] += w * ks[x] * ks[y] - wg * ks[x] * cq


# ---------------------------------------------------------------------------------------------
# Stoner-Wohlfarth random-axis average -- owned by magnetization.py
# ---------------------------------------------------------------------------------------------
# Reduced energy e(theta) = sin^2 theta - 2 s h cos(theta - psi) (s = +1: the field along the
# axis' positive side, s = -1: reversed); a minimum solves F = sin 2t + 2 s h sin(t - psi) = 0.


@nb.njit(cache=True, error_model="numpy")
def sw_root(h, psi, s, lo, hi, x0, xtol, maxit):
    """Root of ``F(t) = sin 2t + 2 s h sin(t - psi)`` in ``[lo, hi]`` (F(lo) <= 0 <= F(hi)) by
    safeguarded Newton (rtsafe; the scalar form of ``magnetization._safe_newton``); returns the
    root and the number of steps (``maxit + 1``: not converged)."""
    x = min(max(x0, lo), hi)
    step = hi - lo
    for it in range(maxit):
        F = math.sin(2.0 * x) + 2.0 * s * h * math.sin(x - psi)
        dF = 2.0 * math.cos(2.0 * x) + 2.0 * s * h * math.cos(x - psi)
        if F == 0.0:
            return x, it + 1
        if F < 0.0:
            lo = x
        else:
            hi = x
        xn = x - F / dF
        if not ((xn >= lo) and (xn <= hi) and (abs(xn - x) <= 0.5 * step)):
            xn = 0.5 * (lo + hi)
        step = abs(xn - x)
        x = xn
        if step <= xtol or hi - lo <= xtol:
            return x, it + 1
    return x, maxit + 1


def _sw_average_impl(hr, kappa, psi, w, tc, hsw, with_slope, maxit, out_m, out_dm, out_it):
    """Random-axis average of the two-state equilibrium ``M/Ms`` (``out_m``) and its slope
    ``d(M/Ms)/dhr`` (``out_dm``, if ``with_slope``) at reduced fields ``hr`` (>= 0) and barrier
    parameters ``kappa`` (inf: T = 0), on the axes ``psi`` with weights ``w``; ``tc`` bounds
    each axis' reversed minimum, ``hsw`` its switching field. ``out_it``: the most Newton steps
    any root of the element took (> maxit: not converged). Each element is independent."""
    for i in nb.prange(hr.shape[0]):
        h = hr[i]
        kap = kappa[i]
        m = 0.0
        dm = 0.0
        worst = 0
        for k in range(psi.shape[0]):
            p = psi[k]
            tp, it = sw_root(h, p, 1.0, 0.0, p, 0.5 * p, 1e-13, maxit)
            worst = max(worst, it)
            ex = h < hsw[k]
            if ex:
                phi, it = sw_root(h, p, -1.0, tc[k], 0.0, 0.5 * tc[k], 1e-13, maxit)
                worst = max(worst, it)
            else:
                phi = 0.5 * tc[k]            # no reversed minimum: its population is 0
            cp = math.cos(tp - p)
            cm = -math.cos(phi - p)
            sphi = math.sin(phi)
            stp = math.sin(tp)
            de = (sphi * sphi + 2.0 * h * math.cos(phi - p)) - (stp * stp - 2.0 * h * cp)
            if not ex:
                pp = 1.0
            elif math.isinf(kap):
                pp = 1.0 if de > 0.0 else 0.5
            else:
                beta = kap * de
                e = math.exp(-abs(beta))
                pp = 1.0 / (1.0 + e) if beta >= 0.0 else e / (1.0 + e)
            m += w[k] * (pp * cp + (1.0 - pp) * cm)
            if with_slope:
                epp = 2.0 * math.cos(2.0 * tp) + 2.0 * h * cp
                dcp = 2.0 * math.sin(tp - p) ** 2 / epp
                dpp = 0.0
                dcm = 0.0
                if ex:
                    epm = 2.0 * math.cos(2.0 * phi) - 2.0 * h * math.cos(phi - p)
                    if epm > 0.0:
                        dcm = 2.0 * math.sin(phi - p) ** 2 / epm
                    if not math.isinf(kap):
                        dpp = pp * (1.0 - pp) * kap * 2.0 * (cp - cm)
                pm = 1.0 - pp
                dm += w[k] * (pp * dcp + (pm * dcm if pm > 0.0 else 0.0) + (cp - cm) * dpp)
        out_m[i] = m
        out_dm[i] = dm
        out_it[i] = worst


sw_average = nb.njit(cache=True, parallel=True, error_model="numpy")(_sw_average_impl)
