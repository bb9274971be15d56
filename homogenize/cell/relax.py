"""Coupled magneto-mechanical equilibrium of an RVE: particles that move.

Each particle is a rigid sphere bonded to the elastic matrix. In a field step the magnetic
forces ``F(x)`` (self-consistent point dipoles, :func:`micro.dipoles.solve`, re-solved at the
current positions) and a short-range contact penalty ``F_c(x)`` displace the particles by

    u = M F(X + u)                                                     (1)

with ``M`` the (3N, 3N) displaceability (compliance) of the rigid particles in the periodic
cell at zero mean strain, evaluated in the reference configuration ``X`` (small-strain
elasticity; the LOAD follows the particles: that is the geometric nonlinearity that makes
neighbours along the field snap together). Equation (1) is solved for ``u`` by Newton's method
with pseudo-transient continuation (the Jacobian ``I - M dF/dx``: contact penalty exact,
magnetic stiffness by differences of the full self-consistent forces for close particles),
field step after field step, each step starting from the previous solution; no particle moves
by more than a quarter of its smallest gap per step, and no step makes particles overlap. A
field step that does not converge, or converges into an overlap (a pair snapping through the
contact penalty in one large step), is retried from the last converged state with the field
increment halved (adaptive sub-stepping, :func:`_substepped`; ``max_substep_halvings``).
Torques: the moments of soft spheres follow their local field (isotropic laws), so point
dipoles carry no torque and the rotations of the spheres (which do not change their positions
to the order of ``M``) are not solved.

Displaceability ``M``:

* ``elastic="green"`` (default, fast): the elastic Rotne-Prager tensor of rigid spheres,
  Ewald-summed in the periodic cell (:mod:`homogenize.cell._green`); exact for one sphere and to
  O(r^-3) for pairs (many-body reflections left out). Model error (results/relax/green_vs_fem.md,
  voxel FEM at 32 and 48 voxels per edge, nu = 0.45): the pair blocks agree with the FEM to
  5 % down to a gap of 0.6 radius, but the reflections that lower the self displaceability of
  a sphere with a close neighbour are missing (FEM: -6.4 % at gap 0.6 a, -2.9 % at 1 a,
  -0.6 % at 2 a), so the relative compliance of a close pair under equal and opposite forces
  is overestimated, after removing the FEM's own single-sphere voxel error, by about 16 % at
  gap 0.6 a, 7 % at 1 a and 2 % at 2 a: close pairs come together somewhat too easily.
* ``elastic="fem"``: the voxel cell FEM with rigid particles, one unit force per particle and
  direction (:func:`fem_displaceability`, 3N cell solves; for small RVEs and for validation).

Macro boundary. The fluctuations are solved at zero mean strain. The relaxed RVE then goes
through the cell FEM (:func:`homogenize.cell.problem.homogenize_mesh`, rigid particles) with its
magnetic forces and pairwise virial: ``C_eff`` (stiffness along and across the field after
restructuring), the magnetic mean stress and, with ``boundary="free"``, the free
magnetostriction ``strain_mag = -C_eff^-1 stress_mag`` (zero mean stress); with
``boundary="strain"`` the mean strain is the prescribed ``E`` (default zero, a clamped cell) and
the mean stress ``C_eff : E + stress_mag`` is reported. The affine strain (~1e-3 .. 1e-2) is not
fed back into the magnetics (it changes pair distances by that relative amount, against the gap
changes of tens of per cent that restructuring makes).

Near field (``near_field=True``): close pairs (surface gap below two mean radii) get the exact
two-sphere force minus the point-dipole force (:mod:`micro.nearfield`, multipole expansion,
chord permeability of each sphere's law at its local field) on top of the periodic point
dipoles; the corrections are pairwise, so they conserve momentum and join the virial. Their
part of the Jacobian comes from the same finite differences as the magnetic stiffness. Inside
the contact layer (gap < ``min_gap_m``) the near-field force is held at its value at the
layer's edge and the contact penalty, stiffened by the square root of the exact/point-dipole
force ratio there (2.1 for mu_r = 1000 at 5 % of a radius; :func:`_near_field_stiffening`),
takes over: the contact force itself is set by the
penalty, not by the (log-divergent, for mu_r -> inf) force of touching spheres.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse.csgraph as csgraph
import scipy.sparse as sp

from micro.common.validate import (ConvergenceError, InputError, check_choice, check_finite,
                             check_range)
from scipy.constants import mu_0 as MU0

from micro.dipoles import _law_jacobian, solve as solve_dipoles
from micro.magnetization import DEFAULT_LAW, MagnetizationLaw, get_law
from micro.materials import PDMS, ElasticMaterial, elastic
from micro.nearfield import MU_MAX, chord_permeability, near_field_correction_N
from micro.box import PeriodicBox
from micro.rve import RVE

from homogenize.cell._pair_kernels import pair_sums
from homogenize.cell._green import periodic_displaceability, rigid_sphere_displaceability
from homogenize.cell.problem import SOLVERS, homogenize_mesh, tensor_to_voigt, voigt_to_tensor
from homogenize.voxels.mesh import voxelize

__all__ = ["relax", "RelaxResult", "equilibrium", "Equilibrium", "fem_displaceability",
           "magnetostriction_curve",
           "green_displaceability", "microstructure", "magnetic_coenergy_J", "BOUNDARIES",
           "ELASTIC_MODELS", "MAX_SUBSTEP_HALVINGS", "pair_contact_forces",
           "rigid_sphere_displaceability"]

BOUNDARIES = ("free", "strain")
ELASTIC_MODELS = ("green", "fem")
#: the Jacobian's magnetic stiffness in :func:`equilibrium` (``stiffness``)
STIFFNESS_MODELS = ("auto", "analytic", "differences")
#: smallest pseudo-time step of :func:`equilibrium` (in units of the relaxation time of the
#: overdamped dynamics du/dt = M F - u)
DT_MIN = 1e-4
#: a pseudo-time step that raises the residual by more than this factor is rejected
REJECT_RISE = 2.0
#: the cell FEM solvers of :func:`relax` (``cell_solver``; homogenize.cell.problem.SOLVERS)
CELL_SOLVERS = SOLVERS


# ------------------------------------------------------------------------------------------
# Elastic response of the rigid particles
# ------------------------------------------------------------------------------------------
def _check_matrix(matrix):
    if not isinstance(matrix, ElasticMaterial):
        raise InputError(f"matrix must be a micro.materials.ElasticMaterial, got "
                         f"{type(matrix).__name__}")
    if not (np.isfinite(matrix.E_Pa) and matrix.E_Pa > 0):
        raise InputError(f"matrix modulus E_Pa must be > 0 Pa, got {matrix.E_Pa}")
    if not -1.0 < matrix.nu <= 0.5:
        raise InputError(f"matrix Poisson's ratio must be in (-1, 0.5], got {matrix.nu}")


def _shear(matrix):
    return matrix.E_Pa / (2.0 * (1.0 + matrix.nu))


def green_displaceability(rve, matrix: ElasticMaterial = elastic(PDMS), *,
                          accuracy: float = 1e-8) -> np.ndarray:
    """Displaceability of the RVE's particles, (3N, 3N) [m/N], from the periodic elastic
    Rotne-Prager tensor (:func:`homogenize.cell._green.periodic_displaceability`)."""
    _check_matrix(matrix)
    return periodic_displaceability(rve.centers_m, rve.radii_m, rve.box_m, _shear(matrix),
                                    matrix.nu, accuracy=accuracy)


def _particle_translation(mesh, W, p):
    """Mean displacement of the nodes of particle p's voxels (its rigid translation) [m]."""
    n = mesh.n
    vox = np.argwhere((mesh.owner == p) & (mesh.fraction >= 0.5))     # (m, 3) as (k, j, i)
    acc = np.zeros(3)
    cnt = 0
    for az in (0, 1):
        for ay in (0, 1):
            for ax in (0, 1):
                k, j, i = (vox[:, 0] + az) % n, (vox[:, 1] + ay) % n, (vox[:, 2] + ax) % n
                acc += W[k, j, i].sum(axis=0)
                cnt += vox.shape[0]
    return acc / cnt


def fem_displaceability(rve, voxels: int, matrix: ElasticMaterial = elastic(PDMS), *,
                        tol: float = 1e-8, particles=None, directions=(0, 1, 2),
                        solver: str = "fast") -> np.ndarray:
    """Displaceability of rigid particles from the periodic voxel cell FEM, (3N, 3N) [m/N].

    A unit force on particle j (spread over its voxels, balanced by a uniform counter-load,
    zero mean strain) is solved with :func:`homogenize.cell.problem.homogenize_mesh` (rigid particles,
    deflated CG); column (j, d) holds the mean nodal displacement of every particle. Costs 3N
    cell solves; ``particles`` (indices) and ``directions`` restrict the loaded particles and
    force directions (other columns zero). ``solver`` goes to the cell FEM (``"fast"``,
    ``"reference"`` or ``"matrix-free"`` for large grids, :func:`homogenize.cell.problem.homogenize_mesh`).

    Conventions as in the cell FEM: the counter-load acts on every voxel, the particle's own
    included (net force ``(1 - phi_p) F`` on it), and the nodal fluctuation has zero mean; both
    differ from the Green's function's by O(phi) in the self terms and cancel in the relative
    displacements of balanced forces.
    """
    _check_matrix(matrix)
    mesh = voxelize(rve, voxels)
    N = mesh.n_particles
    M = np.zeros((3 * N, 3 * N))
    loaded = range(N) if particles is None else particles
    # unit force scaled to the matrix: displacements ~ 1/(G a), keeps CG in its usual range
    for j in loaded:
        for d in directions:
            F = np.zeros((N, 3))
            F[j, d] = 1.0
            res = homogenize_mesh(mesh, forces_N=F, matrix=matrix, rigid=True, cases=(),
                                  keep_fields=True, tol=tol, solver=solver)
            W = res.fields["magnetic"]
            for p in range(N):
                M[3 * p:3 * p + 3, 3 * j + d] = _particle_translation(mesh, W, p)
    return M


# ------------------------------------------------------------------------------------------
# Contact penalty
# ------------------------------------------------------------------------------------------
def _pairs(centers, radii, box, cutoff):
    """Pairs (i < j, sorted by i then j) with surface gap below ``cutoff``: i, j, minimum-image
    d = x_i - x_j, r, gap. The box's pair search proposes every pair within centre distance
    ``cutoff + 2 max(radii)`` (plus a round-off margin); the gap decides, from the centres as
    given."""
    pbox = PeriodicBox(box)
    reach = cutoff + 2.0 * float(radii.max()) + 1e-9 * pbox.L if radii.size else 0.0
    i, j, _ = pbox.pairs_within(centers, reach)
    d = pbox.minimum_image(centers[i] - centers[j])
    r = np.linalg.norm(d, axis=1)
    gap = r - radii[i] - radii[j]
    sel = gap < cutoff
    return i[sel], j[sel], d[sel], r[sel], gap[sel]


def _barrier(g, g0, kc):
    """Contact penalty pair force phi(g) >= 0 (repulsive) and d phi / d g for gaps g < g0.

    Linear in the overlap ``d = g0 - g`` (``kc (d - w/2)``) with a quadratic onset over the first
    ``w = g0 / 10`` (``kc d^2 / (2 w)``): C1-smooth, so Newton does not cycle at its start, and
    of constant stiffness beyond, so its Jacobian is exact over a whole step.
    """
    w = 0.1 * g0
    d = g0 - g
    if d < w:
        return 0.5 * kc * d * d / w, -kc * d / w
    return kc * (d - 0.5 * w), -kc           # (w = 0: pairs placed in contact, linear)


def _activation_gap(X_ref, radii, box, i, j, g0):
    """Gap where the penalty of pair (i, j) starts: g0, or the pair's as-placed gap if smaller
    (particles placed closer than g0 are not pushed apart at zero field) [m]."""
    if X_ref is None or len(i) == 0:
        return np.full(len(i), g0)
    d = PeriodicBox(box).minimum_image(X_ref[i] - X_ref[j])
    return np.minimum(g0, np.maximum(np.linalg.norm(d, axis=1) - radii[i] - radii[j], 0.0))


def _contact(centers, radii, box, g0, k_c, X_ref=None):
    """Barrier forces (N, 3) [N], stiffness dF/dx (3N, 3N) [N/m] and energy [J] of the pairs
    closer than ``g0`` (see :func:`_barrier`; ``k_c`` per particle [N/m])."""
    N = radii.size
    F = np.zeros((N, 3))
    K = np.zeros((3 * N, 3 * N))
    i, j, d, r, g = _pairs(centers, radii, box, g0)
    ga = _activation_gap(X_ref, radii, box, i, j, g0)
    e = 0.0
    for a, b, dv, rv, gv, g0p in zip(i, j, d, r, g, ga):
        if gv >= g0p:
            continue
        kc = 2.0 * k_c[a] * k_c[b] / (k_c[a] + k_c[b])
        phi, dphi = _barrier(gv, g0p, kc)
        n = dv / rv
        F[a] += phi * n
        F[b] -= phi * n
        # dF_a/dx_a = phi' n n + phi / r (I - n n)
        Kab = dphi * np.outer(n, n) + phi / rv * (np.eye(3) - np.outer(n, n))
        sa, sb = slice(3 * a, 3 * a + 3), slice(3 * b, 3 * b + 3)
        K[sa, sa] += Kab
        K[sb, sb] += Kab
        K[sa, sb] -= Kab
        K[sb, sa] -= Kab
        e += _barrier_energy(gv, g0p, kc)
    return F, K, e


def _barrier_energy(g, g0, kc):
    """Energy of the penalty, int_g^g0 phi dg' [J]."""
    w = 0.1 * g0
    d = g0 - g
    if d < w:
        return kc * d ** 3 / (6.0 * w) if w > 0 else 0.0
    return kc * w * w / 6.0 + kc * (0.5 * (d * d - w * w) - 0.5 * w * (d - w))


def _dipole_force(d, mi, mj):
    """Force on dipole i from dipole j at d = x_i - x_j (open space), (..., 3) [N]."""
    r = np.linalg.norm(d, axis=-1)[..., None]
    rh = d / r
    mir = np.sum(mi * rh, axis=-1)[..., None]
    mjr = np.sum(mj * rh, axis=-1)[..., None]
    mm = np.sum(mi * mj, axis=-1)[..., None]
    return 3.0 * MU0 / (4.0 * math.pi * r ** 4) * (mir * mj + mjr * mi + mm * rh
                                                    - 5.0 * mir * mjr * rh)


def _dipole_pair_stiffness(x, moments, a, box, near=2.0):
    """Approximate magnetic stiffness dF/dx (3N, 3N) [N/m]: point-dipole pair forces of near
    pairs (gap < ``near`` mean radii) at frozen moments, by central differences. Used only in
    the Jacobian of the pseudo-time steps (the residual always has the full periodic,
    self-consistent forces), so its approximations slow the convergence, never bias it."""
    N = a.size
    K = np.zeros((3 * N, 3 * N))
    i, j, d, r, g = _pairs(x, a, box, near * float(a.mean()))
    if i.size == 0:
        return K
    h = 1e-4 * r[:, None]
    mi, mj = moments[i], moments[j]
    for c in range(3):
        e = np.zeros(3)
        e[c] = 1.0
        dF = (_dipole_force(d + h * e, mi, mj) - _dipole_force(d - h * e, mi, mj)) / (2 * h)
        for p, q, col in zip(i, j, dF):        # dF_i/dx_i[:, c] = col, dF_i/dx_j = -col
            K[3 * p:3 * p + 3, 3 * p + c] += col
            K[3 * q:3 * q + 3, 3 * q + c] += col
            K[3 * p:3 * p + 3, 3 * q + c] -= col
            K[3 * q:3 * q + 3, 3 * p + c] -= col
    return K


#: Image sums of the analytic magnetic stiffness run over lattice vectors up to this many box
#: edges (the pair terms decay as r^-4 and r^-5; the dipole tensor's conditionally convergent
#: tail is taken in spherical order with the tin-foil correction): the stiffness agrees with
#: differences of the Ewald-summed self-consistent forces to ~1e-3 of its largest entry.
STIFFNESS_IMAGE_CUTOFF_BOXES = 2.0


def _lattice_vectors(L, rc):
    k = int(math.ceil(rc / L)) + 1
    r = np.arange(-k, k + 1)
    n = np.stack(np.meshgrid(r, r, r, indexing="ij"), -1).reshape(-1, 3) * L
    return n[np.einsum("ij,ij->i", n, n) < (rc + math.sqrt(3.0) * L) ** 2]


def magnetic_stiffness_analytic(rve, state, law=DEFAULT_LAW, law_params=None, *,
                                demag_factor=None,
                                cutoff_boxes: float = STIFFNESS_IMAGE_CUTOFF_BOXES) -> np.ndarray:
    """Stiffness ``dF/dx`` (3N, 3N) [N/m] of the self-consistent periodic point-dipole forces
    (:func:`micro.dipoles.solve`, uniform applied field) of the RVE at the magnetic ``state``
    (solved at ``rve.centers_m``), by the implicit function theorem.

    With ``H_i = H_app + sum_j T_ij m_j - N sum_j m_j / V`` (T: periodic dipole tensor),
    ``m_i = m(H_i)`` (differential susceptibility ``D_i = dm/dH``, :func:`micro.dipoles.
    _law_jacobian`) and ``F_i = mu0 sum_j (m_i . grad) T m_j``::

        dm/dx = (I - D T_N)^-1 D dH/dx|_m,     dF/dx = dF/dx|_m + dF/dm dm/dx,

    all terms in closed form from the pair kernel, summed over lattice images up to
    ``cutoff_boxes`` box edges (spherical order; tin-foil ``I/(3V)`` and demagnetizing
    ``-N I/V`` added to every block of T). One dense (3N, 3N) solve: for the small RVEs of
    :func:`relax` it costs less than one dipole solve, against 3 dipole solves per particle
    for finite differences. The image cutoff makes it an approximation to ~1e-3 (tested
    against differences of the Ewald-summed forces); it only steers the Newton iteration.
    """
    x = np.asarray(rve.centers_m, dtype=float)
    N = x.shape[0]
    L = float(rve.box_m)
    V = L ** 3
    m = np.asarray(state.moments_Am2, dtype=float)
    law_obj = law if isinstance(law, MagnetizationLaw) else get_law(law, **dict(law_params or {}))
    if getattr(law_obj, "bind", None) is not None:
        law_obj = law_obj.bind(rve)
    vol = 4.0 / 3.0 * math.pi * np.asarray(rve.radii_m, dtype=float) ** 3
    D = _law_jacobian(law_obj, np.asarray(state.H_local_A_m, dtype=float),
                      np.asarray(rve.m_sat_Am2, dtype=float), vol)
    rc = float(cutoff_boxes) * L
    imgs = _lattice_vectors(L, rc)
    I3 = np.eye(3)
    T, Hx, Fx, Fm = pair_sums(x, m, imgs, rc, MU0)     # (N, N, 3, 3) blocks, numba

    def dense(A):
        return A.transpose(0, 2, 1, 3).reshape(3 * N, 3 * N)

    Tn = dense(T) + np.kron(np.ones((N, N)), I3) * (1.0 / 3.0 - float(demag_factor or 0.0)) / V
    Dm = np.zeros((3 * N, 3 * N))
    for i in range(N):
        Dm[3 * i:3 * i + 3, 3 * i:3 * i + 3] = D[i]
    dmdx = np.linalg.solve(np.eye(3 * N) - Dm @ Tn, Dm @ dense(Hx))
    return dense(Fx) + dense(Fm) @ dmdx


# ------------------------------------------------------------------------------------------
# Near-field magnetic forces beyond point dipoles
# ------------------------------------------------------------------------------------------
#: Near-field pairs: full correction up to a surface gap of NEAR_FIELD_GAPS[0] mean radii,
#: tapered (cos^2) to zero at NEAR_FIELD_GAPS[1]; beyond, the correction is below ~1.5 % of
#: the point-dipole pair force (mu_r = 1000; less for smaller mu_r).
NEAR_FIELD_GAPS = (1.0, 2.0)


def _near_field_stiffening(a_mean, g0, mu_max):
    """Factor on the contact penalty with near-field forces: the square root of the ratio of
    the exact to the point-dipole attraction of two equal spheres along the field at the
    contact-layer gap ``g0`` (sqrt(4.43) = 2.1 for mu_r = 1000 at g0 = 5 % of a radius). A
    compromise, tried on two cases: unstiffened, a pair in contact at 0.3 T overlaps by 2 % of
    a radius (inside the tolerated layer); stiffened by the full ratio, Newton cycles on a
    6-particle RVE with a pair placed in contact; with the square root both converge without
    overlap."""
    from micro.nearfield import pair_polarizabilities, point_dipole_polarizabilities
    R = 2.0 + g0 / a_mean
    ex = pair_polarizabilities(R, 1.0, 1.0, mu_max, mu_max, tol=1e-8)
    pd = point_dipole_polarizabilities(R, 1.0, 1.0, mu_max, mu_max)
    return math.sqrt(max(1.0, ex[2] / pd[2]))


def _taper(gap, g1, g2):
    if gap <= g1:
        return 1.0
    if gap >= g2:
        return 0.0
    return math.cos(0.5 * math.pi * (gap - g1) / (g2 - g1)) ** 2


def _near_field_forces(x, a, box, state, gap_floor_m, mu_max=MU_MAX, tol=1e-6):
    """Pairwise near-field corrections to the periodic point-dipole forces (N, 3) [N] and the
    list of (i, j, d_ij, force on i) for the virial.

    Each close pair (surface gap below ``NEAR_FIELD_GAPS[1]`` mean radii, minimum image) gets
    :func:`micro.nearfield.near_field_correction_N`: the exact two-sphere force minus the
    two-point-dipole force, for the spheres' chord permeabilities
    (:func:`micro.nearfield.chord_permeability`, capped at ``mu_max``) in the background field of
    the pair, i.e. the mean of the two local fields without the partner's dipole field. Gaps
    below ``gap_floor_m`` (inside the contact layer) are evaluated at ``gap_floor_m``: there
    the contact penalty takes over (stiffened by :func:`_near_field_stiffening`).
    """
    N = a.size
    F = np.zeros((N, 3))
    pairs_out = []
    a_mean = float(a.mean())
    g1, g2 = NEAR_FIELD_GAPS[0] * a_mean, NEAR_FIELD_GAPS[1] * a_mean
    i, j, d, r, g = _pairs(x, a, box, g2)
    if i.size == 0:
        return F, pairs_out
    m = np.asarray(state.moments_Am2, dtype=float)
    H = np.asarray(state.H_local_A_m, dtype=float)
    vol = 4.0 / 3.0 * math.pi * a ** 3
    mu = chord_permeability(m, H, vol, mu_max)
    for p, q, dv, rv, gv in zip(i, j, d, r, g):
        w = _taper(gv, g1, g2)
        if w == 0.0 or mu[p] <= 1.0 or mu[q] <= 1.0:
            continue
        n = dv / rv
        # the partner's open-space dipole field at each sphere (d = x_p - x_q)
        Hq = (3.0 * (m[q] @ n) * n - m[q]) / (4.0 * math.pi * rv ** 3)
        Hp = (3.0 * (m[p] @ n) * n - m[p]) / (4.0 * math.pi * rv ** 3)
        Hbg = 0.5 * ((H[p] - Hq) + (H[q] - Hp))
        r_eval = max(rv, a[p] + a[q] + gap_floor_m)
        Fp = w * near_field_correction_N(n * r_eval, a[p], a[q], Hbg, float(mu[p]),
                                         float(mu[q]), tol=tol)
        F[p] += Fp
        F[q] -= Fp
        pairs_out.append((p, q, dv, Fp))
    return F, pairs_out


def _near_field_stiffness(x, a, box, state, gap_floor_m, mu_max, rel_step=1e-4):
    """Stiffness (3N, 3N) [N/m] of the near-field corrections (:func:`_near_field_forces`) at
    frozen moments and local fields, by central differences of the positions of the particles
    in near-field pairs (no dipole solve; zero without such pairs). Jacobian only."""
    N = a.size
    K = np.zeros((3 * N, 3 * N))
    g2 = NEAR_FIELD_GAPS[1] * float(a.mean())
    i, j, _, _, _ = _pairs(x, a, box, g2)
    if i.size == 0:
        return K
    h = rel_step * float(a.mean())
    for p in np.unique(np.concatenate([i, j])):
        for c in range(3):
            dx = np.zeros((N, 3))
            dx[p, c] = h
            fp = _near_field_forces(x + dx, a, box, state, gap_floor_m, mu_max)[0]
            fm = _near_field_forces(x - dx, a, box, state, gap_floor_m, mu_max)[0]
            K[:, 3 * p + c] = ((fp - fm) / (2.0 * h)).ravel()
    return K


# ------------------------------------------------------------------------------------------
# Equilibrium at one field
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Equilibrium:
    """Relaxed particles at one field (SI units).

    Attributes
    ----------
    displacement_m : (N, 3) particle displacements from the reference positions [m]
    centers_m : (N, 3) relaxed centres, wrapped into the cell [m]
    state : MagneticState at the relaxed positions
    contact_force_N : (N, 3) penalty forces [N]
    near_field_force_N : (N, 3) near-field corrections beyond point dipoles [N] (None when off);
        near_field_pairs : their pairs (i, j, d_ij [m], force on i [N]) for the virial
    iterations : Newton iterations; residual_history : relative residual per residual evaluation
    """

    displacement_m: np.ndarray
    centers_m: np.ndarray
    state: object
    contact_force_N: np.ndarray
    iterations: int
    evaluations: int
    residual_history: tuple
    contacts: tuple
    near_field_force_N: np.ndarray | None = None
    near_field_pairs: tuple = ()


def _rve_at(rve, centers):
    return replace(rve, centers_m=PeriodicBox(rve.box_m).wrap(centers))


def magnetic_coenergy_J(state, B_T) -> float:
    """Magnetic co-energy of linearly magnetizable dipoles in a fixed applied field [J]:
    ``-(1/2) sum m_i . B_applied`` (metallic boundary). Its negative gradient with respect to
    the positions is the dipole force (tested); for capped or nonlinear laws it is not."""
    B = np.asarray(B_T, dtype=float)
    B = B if B.ndim else np.array([0.0, 0.0, float(B)])
    return -0.5 * float(np.sum(state.moments_Am2 @ B))


def equilibrium(rve, B_T, M, *, law=DEFAULT_LAW, law_params=None, min_gap_m=None,
                u0_m=None, tol=1e-6, max_iter=60, demag_factor=None, accuracy=1e-6,
                magnetic_tol=1e-10, matrix: ElasticMaterial = elastic(PDMS), fd_gap=0.25,
                max_fd=12, near_field: bool = False,
                near_field_mu_max: float = MU_MAX, stiffness: str = "auto",
                trust_dt: bool = True, reject_rise: bool = True) -> Equilibrium:
    """Solve ``u = M F(X + u)`` at one applied field (see the module docstring).

    Parameters
    ----------
    rve : RVE -- reference configuration X
    B_T : float or (3,) -- applied flux density mu0 H [T] (scalar: along z)
    M : ndarray, shape (3N, 3N) -- displaceability [m/N] (:func:`green_displaceability`)
    min_gap_m : float -- surface gap where the contact penalty starts [m] (default 5 % of the
        mean radius); pairs below it are reported as in contact
    u0_m : (N, 3) initial displacements [m] (continuation from the previous step)
    tol : float -- converged when max |u - M F| < tol * mean radius
    matrix : the matrix material (only for the penalty stiffness scale)
    fd_gap, max_fd : the Jacobian's magnetic stiffness by differences of the full forces for at
        most ``max_fd`` particles closer than ``fd_gap`` mean radii to a neighbour (cost: 3 dipole
        solves per particle); the Jacobian only steers the iteration, the residual is exact
    near_field : bool -- add the near-field corrections beyond point dipoles of close pairs
        (:func:`_near_field_forces`, :mod:`micro.nearfield`) to the magnetic forces
    near_field_mu_max : cap of the chord relative permeability in the near-field model
    stiffness : {"auto", "analytic", "differences"} -- the Jacobian's magnetic stiffness:
        ``"analytic"`` (= ``"auto"``): :func:`magnetic_stiffness_analytic` (implicit function
        theorem on the self-consistent moments, no dipole solve, every iteration), plus the
        near-field corrections' stiffness at frozen moments and fields by central differences
        (:func:`_near_field_stiffness`); or ``"differences"``: differences of the full forces
        for at most ``max_fd`` close particles (``fd_gap``; refreshed every 5 iterations; the
        former default: it misses the pairs beyond ``max_fd``, so it converges linearly at
        best on dense RVEs)
    trust_dt, reject_rise : the safeguards of the pseudo-transient iteration (default on):
        a step the trust region would cut below half is re-solved with a shorter pseudo-time
        step, and a step that raises the residual by more than ``REJECT_RISE`` is rejected
        and retried with dt / 4 (off: the former iteration, for comparison)

    Raises
    ------
    ConvergenceError -- no convergence in ``max_iter`` Newton iterations, or particles overlap.
    """
    N = rve.n
    X = np.asarray(rve.centers_m, dtype=float)
    a = np.asarray(rve.radii_m, dtype=float)
    L = float(rve.box_m)
    a_mean = float(a.mean())
    g0 = 0.05 * a_mean if min_gap_m is None else float(min_gap_m)
    if not g0 > 0:
        raise InputError(f"min_gap_m must be > 0 m, got {min_gap_m}")
    k_c = _contact_stiffness(a, matrix)
    if near_field:
        k_c = k_c * _near_field_stiffening(a_mean, g0, near_field_mu_max)
    law_params = dict(law_params or {})
    check_choice("stiffness", stiffness, STIFFNESS_MODELS)
    if stiffness == "auto":
        stiffness = "analytic"
    last = {"m": None, "state": None, "Fc": None, "nf": None}
    nf_floor = g0               # near-field forces inside the contact layer: at its edge

    def magnetic(x, st):
        """Total magnetic force (N, 3): periodic point dipoles (+ near-field corrections)."""
        if not near_field:
            return st.total_force_N, None
        Fn, pairs_nf = _near_field_forces(x, a, L, st, nf_floor, near_field_mu_max)
        return st.total_force_N + Fn, (Fn, tuple(pairs_nf))

    if M.shape != (3 * N, 3 * N):
        raise InputError(f"M must have shape ({3 * N}, {3 * N}) [m/N], got {M.shape}")
    hist = []

    def forces(u):
        x = X + u
        st = solve_dipoles(_rve_at(rve, x), B_T, 0.0, law, demag_factor=demag_factor,
                           tol=magnetic_tol, accuracy=accuracy, initial_moments_Am2=last["m"],
                           **law_params)
        last["m"] = st.moments_Am2
        Fc, Kc, _ = _contact(x, a, L, g0, k_c, X)
        return st, Fc, Kc

    def magnetic_stiffness(u, st):
        """dF/dx: forward differences of the full self-consistent periodic forces for (up to
        ``max_fd``) particles with a neighbour closer than ``fd_gap`` radii, where the moments
        respond strongly to the positions; frozen-moment pair stiffness for the others (each
        difference column costs one dipole solve)."""
        x = X + u
        if stiffness == "analytic":
            K = magnetic_stiffness_analytic(_rve_at(rve, x), st, law, law_params,
                                            demag_factor=demag_factor)
            if near_field:
                K += _near_field_stiffness(x, a, L, st, nf_floor, near_field_mu_max)
            return K
        K = _dipole_pair_stiffness(x, st.moments_Am2, a, L)
        ii, jj, _, _, _ = _pairs(x, a, L, fd_gap * a_mean)
        close = np.unique(np.concatenate([ii, jj]))[:max_fd]
        if close.size == 0:
            return K
        F0 = magnetic(x, st)[0].ravel()
        h = 1e-4 * a_mean
        for p in close:
            for c in range(3):
                du = np.zeros((N, 3))
                du[p, c] = h
                sp_ = solve_dipoles(_rve_at(rve, x + du), B_T, 0.0, law,
                                    demag_factor=demag_factor, tol=magnetic_tol,
                                    accuracy=accuracy, initial_moments_Am2=st.moments_Am2,
                                    **law_params)
                K[:, 3 * p + c] = (magnetic(x + du, sp_)[0].ravel() - F0) / h
        return K

    def resid(y):
        u = y.reshape(N, 3) * a_mean
        st, Fc, _ = forces(u)
        Fm, nf = magnetic(X + u, st)
        last["state"], last["Fc"], last["nf"] = st, Fc, nf
        r = (u.ravel() - M @ (Fm + Fc).ravel()) / a_mean
        hist.append(float(np.abs(r).max()))
        return r

    u_init = np.zeros((N, 3)) if u0_m is None else np.asarray(u0_m, dtype=float)
    y = u_init.ravel() / a_mean
    # Pseudo-transient continuation (Kelley & Keyes 1998) on the overdamped dynamics
    # du/dt = M F(X + u) - u, whose attracting fixed points are the STABLE equilibria: a step
    # solves (I/dt + I - M K) dy = r with an approximate stiffness K (contact penalty exact,
    # dipole pairs at frozen moments); dt grows as the residual falls (switched evolution
    # relaxation), which turns the steps into Newton steps near the solution and lets the
    # particles snap through to contact where the field makes the as-placed branch unstable.
    r = -resid(y)
    rn = float(np.abs(r).max())
    dt = 1.0e3       # start as Newton; the pseudo-time damping enters when the residual rises
    n_newton = 0
    Kmag, k_mag = None, 0
    accepted = (last["state"], last["m"])
    ok = rn < tol
    while not ok and n_newton < max_iter:
        n_newton += 1
        u = y.reshape(N, 3) * a_mean
        x = X + u
        _, Kc, _ = _contact(x, a, L, g0, k_c, X)
        if Kmag is None or (n_newton - k_mag) >= (1 if stiffness == "analytic" else 5):
            Kmag, k_mag = magnetic_stiffness(u, last["state"]), n_newton
        MK = M @ (Kc + Kmag)
        # trust region in physical terms: no pair closes more than half of its current gap
        # (plus a tenth of the contact layer) in one step, so a snap-through towards contact is
        # followed in steps instead of jumping into an overlap
        ii, jj, dd, rr, gg = _pairs(x, a, L, 0.5 * a_mean)
        nn_ = dd / rr[:, None]
        allowed = 0.5 * np.maximum(gg, 0.0) + 0.1 * g0
        while True:
            dy = np.linalg.solve((1.0 + 1.0 / dt) * np.eye(3 * N) - MK, r)
            du = dy.reshape(N, 3) * a_mean
            approach = -np.einsum("ij,ij->i", du[ii] - du[jj], nn_)
            scale = float(min(1.0, np.min(allowed / np.maximum(approach, 1e-300),
                                          initial=1.0)))
            if not trust_dt or scale >= 0.5 or dt <= DT_MIN:
                break
            # a step the trust region would cut is no Newton step: shorten the pseudo-time
            # step instead, so the iterate follows the overdamped dynamics (towards a stable
            # equilibrium) rather than a truncated Newton direction (which can aim at an
            # unstable one and cycle)
            dt = max(dt * max(scale, 0.01), DT_MIN)
        y_new = y + scale * dy
        r_new = -resid(y_new)
        rn_new = float(np.abs(r_new).max())
        if not np.isfinite(rn_new) or (reject_rise and rn_new > REJECT_RISE * rn
                                       and dt > DT_MIN):
            # rejected (the residual rose steeply: the linear model failed, typically a
            # contact switching on or off within the step): back to the last accepted state
            # with a shorter pseudo-time step
            dt = max(dt / 4.0, DT_MIN)
            last["state"], last["m"] = accepted
            continue
        # switched evolution relaxation, asymmetric: grow dt with the residual ratio (at least
        # x2) when the residual falls, shrink it only by the square root of the ratio when it
        # rises (a snap-through or a damped two-cycle must not freeze dt)
        ratio = np.linalg.norm(r) / max(np.linalg.norm(r_new), 1e-300)
        dt = min(dt * max(ratio, 2.0), 1e12) if ratio > 1.0 else max(dt * math.sqrt(ratio), DT_MIN)
        y, r, rn = y_new, r_new, rn_new
        accepted = (last["state"], last["m"])
        ok = rn < tol
    u = y.reshape(N, 3) * a_mean
    if not ok:
        raise ConvergenceError(
            f"relaxation at B = {np.linalg.norm(np.atleast_1d(B_T)):.4g} T did not converge to "
            f"max |u - M F| < {tol:.0e} radii ({len(hist)} residual evaluations; last "
            + ", ".join(f"{v:.1e}" for v in hist[-4:]) + ")", hist)
    st, Fc, _ = forces(u)
    x = X + u
    _, nf = magnetic(x, st)
    i, j, d, rr, g = _pairs(x, a, L, g0)
    if np.any(g < -g0):
        k = int(np.argmin(g))
        raise ConvergenceError(
            f"particles {i[k]} and {j[k]} overlap by {-g[k]:.3g} m (more than the contact "
            f"layer {g0:.3g} m) after relaxation at "
            f"B = {np.linalg.norm(np.atleast_1d(B_T)):.4g} T: the contact penalty is too soft "
            f"for these forces (raise min_gap_m)", hist)
    return Equilibrium(displacement_m=u, centers_m=PeriodicBox(L).wrap(x), state=st, contact_force_N=Fc,
                       iterations=n_newton, evaluations=len(hist), residual_history=tuple(hist),
                       contacts=tuple((int(p), int(q)) for p, q in zip(i, j)),
                       near_field_force_N=None if nf is None else nf[0],
                       near_field_pairs=() if nf is None else nf[1])


# ------------------------------------------------------------------------------------------
# Microstructure descriptors
# ------------------------------------------------------------------------------------------
def microstructure(rve, direction=(0.0, 0.0, 1.0), *, near_gap_m=None, chain_gap_m=None,
                   chain_angle_deg=30.0) -> dict:
    """Descriptors of the arrangement relative to the field direction (SI units).

    * ``pair_anisotropy_P2``: <P2(cos theta)> over near pairs (surface gap < ``near_gap_m``,
      default one mean radius), theta the angle of the pair axis to the field: 0 for an
      isotropic arrangement, > 0 when near neighbours line up along the field, -1/2 across.
    * ``nn_gap_m``: quantiles (min, p10, p50, p90) of each particle's nearest surface gap [m].
    * ``chain_fraction``: fraction of particles in chains, i.e. connected clusters of >= 3
      particles linked by bonds with gap < ``chain_gap_m`` (default 10 % of the mean radius)
      within ``chain_angle_deg`` of the field.
    """
    c = np.asarray(rve.centers_m, dtype=float)
    a = np.asarray(rve.radii_m, dtype=float)
    n = np.asarray(direction, dtype=float)
    n = n / np.linalg.norm(n)
    a_mean = float(a.mean())
    near = a_mean if near_gap_m is None else near_gap_m
    cg = 0.1 * a_mean if chain_gap_m is None else chain_gap_m
    N = a.size
    iu, ju = np.triu_indices(N, 1)
    d = PeriodicBox(rve.box_m).minimum_image(c[iu] - c[ju])
    r = np.linalg.norm(d, axis=1)
    gap = r - a[iu] - a[ju]
    cos = np.abs(d @ n) / r
    sel = gap < near
    P2 = float(np.mean(1.5 * cos[sel] ** 2 - 0.5)) if sel.any() else 0.0
    nn = np.full(N, np.inf)
    np.minimum.at(nn, iu, gap)
    np.minimum.at(nn, ju, gap)
    bond = (gap < cg) & (cos > math.cos(math.radians(chain_angle_deg)))
    A = sp.coo_matrix((np.ones(bond.sum()), (iu[bond], ju[bond])), shape=(N, N))
    _, lab = csgraph.connected_components(A, directed=False)
    sizes = np.bincount(lab)
    chain = float(np.mean(sizes[lab] >= 3))
    q = np.percentile(nn, [10, 50, 90]) if N > 1 else [np.nan] * 3
    return {"pair_anisotropy_P2": P2, "near_pairs": int(sel.sum()),
            "nn_gap_m": {"min": float(nn.min()), "p10": float(q[0]), "p50": float(q[1]),
                         "p90": float(q[2])},
            "chain_fraction": chain}


# ------------------------------------------------------------------------------------------
# Field sweep
# ------------------------------------------------------------------------------------------
def _young_along(C_voigt, n):
    """Young's modulus along unit vector n from a 6x6 Voigt stiffness (engineering shear) [Pa]."""
    S = np.linalg.inv(C_voigt)
    # uniaxial stress n n in Voigt form (11, 22, 33, 23, 13, 12); S maps it to the engineering
    # strains (gamma = 2 eps), whose product with the stress Voigt vector is n.eps.n
    s = np.array([n[0] ** 2, n[1] ** 2, n[2] ** 2, n[1] * n[2], n[0] * n[2], n[0] * n[1]])
    return 1.0 / float(s @ S @ s)


def _perpendicular(n):
    t = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = t - (t @ n) * n
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


@dataclass(frozen=True, eq=False)
class RelaxResult:
    """Field sweep of the coupled RVE (SI units).

    Attributes
    ----------
    steps : tuple of dict -- per field step (see :meth:`to_dict`)
    rve : RVE -- the relaxed RVE at the last field step (saves with ``RVE.save``)
    rves : tuple of RVE -- the relaxed RVE at every step
    settings : dict -- the configuration of the run
    """

    steps: tuple
    rve: RVE
    rves: tuple
    settings: dict
    timings_s: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-serialisable: ``settings``, ``timings_s`` and ``steps`` (each with ``B_T``,
        ``strain_mag`` (3x3), ``stress_mag_Pa`` (3x3), ``M_eff_A_per_m``,
        ``E_eff_parallel_Pa``, ``E_eff_perpendicular_Pa``, ``min_gap_m``,
        ``displacement_rms_m``, ``iterations``, ``contacts``, ``microstructure``...)."""
        return {"settings": self.settings, "timings_s": self.timings_s,
                "steps": [dict(s) for s in self.steps]}


#: Default limit of the adaptive field sub-stepping of :func:`relax`: a requested step is
#: retried with its field increment halved at most this many times (down to 1/32 of it).
MAX_SUBSTEP_HALVINGS = 5


def _substepped(rve, M, n, B_from, B_to, u_from, eq_kw, max_halvings):
    """Equilibrium at the field ``B_to`` (along unit ``n``) by continuation from the converged
    state ``u_from`` at ``B_from`` [T], with adaptive sub-stepping.

    A trial (sub-)step that raises ConvergenceError (no convergence, or overlapping particles)
    is discarded and retried from the last converged state with the increment halved; after two
    converged sub-steps in a row the increment doubles again (at most back to the requested
    one). At
    most ``max_halvings`` halvings per requested step, then ConvergenceError with every
    attempt. Returns the Equilibrium at ``B_to`` and a summary dict (``substeps``,
    ``fields_T``, ``iterations``, ``evaluations``, ``failed``)."""
    full = B_to - B_from
    h = full
    B_c, u_c = B_from, u_from
    halvings = 0
    fields, failed, attempts = [], [], []
    its = evals = 0
    eq = None
    while eq is None or B_c < B_to:
        B_try = B_to if (B_to - B_c) <= h * (1.0 + 1e-9) else B_c + h
        try:
            e = equilibrium(rve, B_try * n, M, u0_m=u_c, **eq_kw)
        except ConvergenceError as exc:
            hist = list(exc.residual_history)
            attempts.append({"B_T": float(B_try), "from_B_T": float(B_c), "converged": False,
                             "residual_history": hist, "message": str(exc)})
            failed.append({"B_T": float(B_try), "from_B_T": float(B_c),
                           "residual_evaluations": len(hist),
                           "last_residual": float(hist[-1]) if hist else None})
            halvings += 1
            if halvings > max_halvings or not h > 0:
                lines = "; ".join(
                    f"{a['from_B_T']:.4g} -> {a['B_T']:.4g} T: "
                    + ("converged" if a["converged"] else
                       f"failed after {len(a['residual_history'])} residual evaluations, "
                       "residuals " + ", ".join(f"{v:.1e}" for v in a["residual_history"][-3:]))
                    for a in attempts)
                err = ConvergenceError(
                    f"relaxation did not reach the requested B = {B_to:.4g} T: the step from "
                    f"{B_c:.4g} T failed at B = {B_try:.4g} T even with the field increment "
                    f"halved {halvings - 1} times (max_substep_halvings = {max_halvings}). "
                    f"Attempts: {lines}. Last failure: {exc}",
                    [v for a in attempts for v in a["residual_history"]])
                err.attempts = attempts
                raise err from None
            h = 0.5 * h
            continue
        attempts.append({"B_T": float(B_try), "from_B_T": float(B_c), "converged": True,
                         "residual_history": list(e.residual_history), "message": ""})
        its += e.iterations
        evals += e.evaluations
        fields.append(float(B_try))
        # the increment doubles again after two converged sub-steps in a row
        if attempts[-2:-1] and attempts[-2]["converged"]:
            h = min(2.0 * h, full)
        eq, B_c, u_c = e, B_try, e.displacement_m
    return eq, {"substeps": len(fields), "fields_T": fields, "iterations": its,
                "evaluations": evals, "failed": failed}



#: The particle relaxations of the last sweeps (:func:`relax`): the same RVE relaxed through
#: the same field steps with the same solver settings and displaceability is the same path
#: (a deterministic computation), e.g. the fine and the coarse cell FEM of a batch's two-grid
#: estimate; the cell FEM is run again on every call.
_SWEEP_CACHE: dict = {}
_SWEEP_CACHE_SIZE = 2


def clear_sweep_cache() -> None:
    """Forget the cached particle relaxations (a benchmark that times :func:`relax` twice on the
    same inputs must not hand the second run the first one's path)."""
    _SWEEP_CACHE.clear()


def _sweep_key(rve, M, n, B, eq_kw, max_halvings):
    """A digest of everything the particle relaxation of :func:`relax` depends on, or None
    (no caching) when an input does not pickle (e.g. a law object)."""
    import hashlib
    import pickle
    if not isinstance(eq_kw.get("law"), str):
        return None
    try:
        blob = pickle.dumps((rve, np.asarray(M), np.asarray(n), np.asarray(B),
                             sorted((k, repr(v)) for k, v in eq_kw.items()), int(max_halvings)),
                            protocol=4)
    except Exception:                                   # noqa: BLE001 -- then no caching
        return None
    return hashlib.sha256(blob).hexdigest()


def relax(rve, B_steps_T, *, law=DEFAULT_LAW, law_params=None,
          matrix: ElasticMaterial = elastic(PDMS), boundary: str = "free", voxels: int | None = 32,
          near_field: bool = False, elastic_model: str = "green", direction=(0.0, 0.0, 1.0),
          min_gap_m: float | None = None, tol: float = 1e-6, max_iter: int = 60,
          demag_factor=None, accuracy: float = 1e-6, cell_tol: float = 1e-6,
          progress: bool = False, mean_strain=None,
          near_field_mu_max: float = MU_MAX,
          max_substep_halvings: int = MAX_SUBSTEP_HALVINGS, cell_solver: str = "auto",
          cell_warm_start: bool = True) -> RelaxResult:
    """Relax an RVE through increasing field steps (coupled magneto-mechanics).

    Parameters
    ----------
    rve : RVE -- the as-placed (reference) RVE
    B_steps_T : sequence of float -- applied flux density mu0 H per step [T], strictly
        increasing and >= 0, along ``direction``
    law, law_params : magnetization law (:func:`micro.magnetization.get_law`) and parameters
    matrix : ElasticMaterial -- the matrix (E_Pa > 0, nu); particles are rigid
    boundary : {"free", "strain"} -- zero mean stress (free magnetostriction ``strain_mag``)
        or the prescribed mean strain ``mean_strain`` (default zero: a clamped cell); each step
        reports ``mean_strain`` and ``mean_stress_Pa`` (3x3): free: the magnetostriction and
        zero; strain: the prescribed strain and ``C_eff : mean_strain + stress_mag_Pa``
    mean_strain : (3, 3) symmetric, or None -- prescribed mean (small) strain of the cell for
        ``boundary="strain"`` [-], |entries| <= 0.1. It enters the mean stress linearly; like
        the free magnetostriction it is not fed back into the particle positions of the
        magnetics (an affine strain changes pair distances by its own relative amount)
    voxels : int or None -- voxels per edge of the cell FEM on the relaxed RVE (C_eff, mean
        stress, strain); None skips it (no strain, no E_eff)
    near_field : bool -- add the near-field corrections beyond point dipoles of close pairs
        (exact two-sphere multipole forces minus point-dipole ones, :mod:`micro.nearfield`,
        chord permeability capped at ``near_field_mu_max``; pairwise additive)
    elastic_model : {"green", "fem"} -- displaceability from the periodic elastic Green's
        function (fast) or from the voxel FEM (3N cell solves at ``voxels``)
    direction : (3,) -- field direction
    min_gap_m : float -- contact gap [m] (default 5 % of the mean radius)
    tol, max_iter : Newton tolerance (in radii) and iteration budget per (sub-)step
    max_substep_halvings : int -- adaptive field sub-stepping: a step that does not converge
        (or ends with overlapping particles) is retried from the last converged state with
        the field increment halved, at most this many times per requested step (default
        ``MAX_SUBSTEP_HALVINGS`` = 5: increments down to 1/32 of the requested one; 0 switches
        sub-stepping off). After two converged sub-steps in a row the increment doubles again
        (never beyond the requested one). Each step reports ``substeps`` (converged solves it took,
        1 without sub-stepping), ``substep_B_T`` (their fields) and ``failed_attempts``
        (field, starting field, residual evaluations and last residual of each failed try)
    demag_factor, accuracy : passed to :func:`micro.dipoles.solve`
    cell_tol : CG tolerance of the cell FEM
    cell_solver : the cell FEM's solver (:func:`homogenize.cell.problem.homogenize_mesh`; default
        "auto"), with "fast" and then "reference" as fallbacks on a relaxed RVE where it fails
    cell_warm_start : bool -- start the cell FEM's CG of every field step from the previous
        step's solutions (:meth:`homogenize.cell.problem._CellSolver.initial_guess`: the relaxed RVE
        moves little between steps); same stopping rule, so the results agree with cold starts
        to ``cell_tol``. False: every step from scratch

    Returns
    -------
    RelaxResult

    Raises
    ------
    InputError -- steps not increasing, matrix modulus <= 0, unknown options.
    ConvergenceError -- a step does not converge or particles overlap even with the field
        increment halved ``max_substep_halvings`` times; the message names the requested
        and the failed field and summarises every attempt, ``residual_history`` concatenates
        the residual histories of all attempts (``attempts``: one dict per attempt).
    """
    t_all = time.perf_counter()
    B = np.asarray(check_finite("B_steps_T", B_steps_T, "T"), dtype=float).ravel()
    if B.size == 0:
        raise InputError("B_steps_T must hold at least one field step [T]")
    if np.any(B < 0) or np.any(np.diff(B) <= 0):
        raise InputError(f"B_steps_T must be >= 0 T and strictly increasing, got "
                         f"{np.array2string(B, precision=4)}")
    _check_matrix(matrix)
    check_choice("boundary", boundary, BOUNDARIES)
    check_choice("elastic_model", elastic_model, ELASTIC_MODELS)
    if not isinstance(near_field, (bool, np.bool_)):
        raise InputError(f"near_field must be True or False, got {near_field!r}")
    check_range("near_field_mu_max", near_field_mu_max, 1.0, 1e6, "(relative permeability)",
                lo_open=True)
    E_mean = _check_mean_strain(mean_strain, boundary)
    if (isinstance(max_substep_halvings, (bool, np.bool_))
            or not isinstance(max_substep_halvings, (int, np.integer))
            or not 0 <= max_substep_halvings <= 20):
        raise InputError(f"max_substep_halvings must be an integer in [0, 20], got "
                         f"{max_substep_halvings!r}")
    if voxels is None and elastic_model == "fem":
        raise InputError("elastic_model='fem' needs voxels")
    n = np.asarray(direction, dtype=float)
    if n.shape != (3,) or not np.linalg.norm(n) > 0:
        raise InputError(f"direction must be a nonzero 3-vector, got {direction!r}")
    n = n / np.linalg.norm(n)
    t = {"displaceability": 0.0, "relax": 0.0, "cell": 0.0}
    t0 = time.perf_counter()
    if elastic_model == "green":
        M = green_displaceability(rve, matrix)
    else:
        M = fem_displaceability(rve, voxels, matrix)
    t["displaceability"] = time.perf_counter() - t0
    e1, e2 = _perpendicular(n)
    a_mean = float(np.mean(rve.radii_m))
    stiffen = (_near_field_stiffening(a_mean, min_gap_m if min_gap_m is not None
                                      else 0.05 * a_mean, near_field_mu_max)
               if near_field else 1.0)
    check_choice("cell_solver", cell_solver, CELL_SOLVERS)
    steps, rves = [], []
    cell_guess = None              # the previous field step's cell FEM solutions (warm start)
    u = np.zeros((rve.n, 3))
    B_done = 0.0                   # field of the last converged state (u = 0 at zero field)
    eq_kw = dict(law=law, law_params=law_params, min_gap_m=min_gap_m, tol=tol,
                 max_iter=max_iter, demag_factor=demag_factor, accuracy=accuracy, matrix=matrix,
                 near_field=bool(near_field), near_field_mu_max=near_field_mu_max)
    ckey = _sweep_key(rve, M, n, B, eq_kw, max_substep_halvings)
    cached = _SWEEP_CACHE.get(ckey) if ckey is not None else None
    path = []                      # (Equilibrium, sub-stepping summary) per field step
    for k, Bk in enumerate(B):
        t0 = time.perf_counter()
        if cached is not None:
            eq, sub = cached[k]
        else:
            eq, sub = _substepped(rve, M, n, B_done, float(Bk), u, eq_kw, max_substep_halvings)
            path.append((eq, sub))
        t["relax"] += time.perf_counter() - t0
        u = eq.displacement_m
        B_done = float(Bk)
        r_rel = replace(rve, centers_m=eq.centers_m,
                        params={**dict(rve.params), "relaxed_B_T": float(Bk),
                                "relaxed_boundary": boundary})
        rves.append(r_rel)
        st = eq.state
        rec = {"B_T": float(Bk),
               "M_eff_A_per_m": float(np.asarray(st.M_eff_A_per_m) @ n),
               "M_eff_vector_A_per_m": np.asarray(st.M_eff_A_per_m).tolist(),
               "displacement_rms_m": float(np.sqrt(np.mean(np.sum(u ** 2, axis=1)))),
               "displacement_max_m": float(np.sqrt(np.sum(u ** 2, axis=1)).max()),
               "iterations": int(sub["iterations"]),
               "residual_evaluations": int(sub["evaluations"]),
               "substeps": int(sub["substeps"]), "substep_B_T": sub["fields_T"],
               "failed_attempts": sub["failed"],
               "contacts": [list(p) for p in eq.contacts], "n_contacts": len(eq.contacts),
               "virial_stress_Pa": np.asarray(st.virial_stress_Pa).tolist()}
        ms = microstructure(r_rel, n)
        rec["min_gap_m"] = ms["nn_gap_m"]["min"]
        rec["microstructure"] = ms
        if near_field:
            Fn = eq.near_field_force_N
            Fp = st.total_force_N
            rec["near_field_pairs"] = len(eq.near_field_pairs)
            rec["near_field_force_max_N"] = float(np.abs(Fn).max()) if Fn is not None else 0.0
            rec["point_dipole_force_max_N"] = float(np.abs(Fp).max())
        rec["strain_mag"] = rec["stress_mag_Pa"] = None
        rec["mean_strain"] = rec["mean_stress_Pa"] = None
        rec["E_eff_parallel_Pa"] = rec["E_eff_perpendicular_Pa"] = None
        if voxels is not None:
            t0 = time.perf_counter()
            forces = st.total_force_N + eq.contact_force_N
            # contact forces are pairwise too: their virial joins the dipoles'
            vir = np.asarray(st.virial_stress_Pa, dtype=float).copy()
            if near_field and eq.near_field_force_N is not None:
                forces = forces + eq.near_field_force_N
                for (_, _, dv, fv) in eq.near_field_pairs:      # pairwise: virial too
                    vir -= np.outer(dv, fv) / rve.box_m ** 3
            g0 = min_gap_m if min_gap_m is not None else 0.05 * float(np.mean(rve.radii_m))
            for (_, _, dv, fv) in _pair_contact_forces(eq.centers_m, np.asarray(rve.radii_m),
                                                       rve.box_m, g0, matrix,
                                                       np.asarray(rve.centers_m), stiffen):
                vir -= np.outer(dv, fv) / rve.box_m ** 3
            res = _cell(voxelize(r_rel, voxels), forces, vir, matrix, cell_tol, cell_solver,
                        cell_guess)
            t["cell"] += time.perf_counter() - t0
            if isinstance(res, str):          # the cell FEM failed on this geometry
                rec["cell_error"] = res
                steps.append(rec)
                continue
            if cell_warm_start:
                cell_guess = res.solution
            rec["cell_solver"] = res.settings["solver"]
            rec["cell_iterations"] = dict(res.iterations)
            C = res.C_eff_Pa
            sig_mag = np.asarray(res.stress_mag_Pa, dtype=float)
            rec["stress_mag_Pa"] = sig_mag.tolist()
            if boundary == "free":
                rec["strain_mag"] = np.asarray(res.strain_mag).tolist()
                rec["mean_strain"] = rec["strain_mag"]
                rec["mean_stress_Pa"] = np.zeros((3, 3)).tolist()
            else:
                # mean stress of the cell at the prescribed mean strain E: C_eff : E + stress_mag
                # (the free case is the E at which it vanishes, E = strain_mag)
                sv = np.asarray(C) @ tensor_to_voigt(E_mean, engineering=True) \
                    + tensor_to_voigt(sig_mag)
                rec["strain_mag"] = E_mean.tolist()
                rec["mean_strain"] = E_mean.tolist()
                rec["mean_stress_Pa"] = voigt_to_tensor(sv).tolist()
            rec["E_eff_parallel_Pa"] = _young_along(C, n)
            rec["E_eff_perpendicular_Pa"] = 0.5 * (_young_along(C, e1) + _young_along(C, e2))
            rec["E_eff_isotropic_Pa"] = float(res.E_eff_Pa)
            rec["C_eff_Pa"] = np.asarray(C).tolist()
        steps.append(rec)
        if progress:
            print(f"B = {Bk:.3f} T: {sub['iterations']} Newton its in {sub['substeps']} "
                  f"sub-step(s), u_rms {rec['displacement_rms_m']:.3g} m, contacts "
                  f"{rec['n_contacts']}", flush=True)
    if ckey is not None and cached is None:
        while len(_SWEEP_CACHE) >= _SWEEP_CACHE_SIZE:
            _SWEEP_CACHE.pop(next(iter(_SWEEP_CACHE)))
        _SWEEP_CACHE[ckey] = tuple(path)
    t["total"] = time.perf_counter() - t_all
    settings = {"law": law if isinstance(law, str) else getattr(law, "name", str(law)),
                "law_params": dict(law_params or {}), "matrix_E_Pa": matrix.E_Pa,
                "matrix_nu": matrix.nu, "boundary": boundary, "voxels": voxels,
                "near_field": bool(near_field), "elastic_model": elastic_model,
                "near_field_mu_max": float(near_field_mu_max) if near_field else None,
                "mean_strain": E_mean.tolist() if boundary == "strain" else None,
                "direction": n.tolist(), "min_gap_m": min_gap_m, "tol": tol,
                "n_particles": rve.n, "box_m": rve.box_m, "phi": rve.phi,
                "demag_factor": demag_factor,
                "max_substep_halvings": int(max_substep_halvings),
                "cell_solver": cell_solver, "cell_warm_start": bool(cell_warm_start)}
    return RelaxResult(steps=tuple(steps), rve=rves[-1], rves=tuple(rves), settings=settings,
                       timings_s=t)


def _check_mean_strain(mean_strain, boundary):
    """The prescribed mean strain (3, 3) [-] of ``boundary="strain"`` (zero if None)."""
    if mean_strain is None:
        return np.zeros((3, 3))
    if boundary != "strain":
        raise InputError(f"mean_strain is prescribed only with boundary='strain' (boundary "
                         f"{boundary!r} has zero mean stress)")
    E = np.asarray(check_finite("mean_strain", mean_strain, "(strain)"), dtype=float)
    if E.shape != (3, 3):
        raise InputError(f"mean_strain must be a 3x3 strain tensor, got shape {E.shape}")
    if np.abs(E - E.T).max() > 1e-12 * max(np.abs(E).max(), 1e-300):
        raise InputError("mean_strain must be symmetric (a small-strain tensor)")
    if np.abs(E).max() > 0.1:
        raise InputError(f"mean_strain entries must be in [-0.1, 0.1] (small strain), got "
                         f"max |E| = {np.abs(E).max():g}")
    return 0.5 * (E + E.T)


def _cell(mesh, forces, virial, matrix, tol, solver="auto", initial_guess=None):
    """Cell FEM with rigid particles on a relaxed RVE, started from ``initial_guess`` (the
    previous step's solutions; its ``solution`` is kept for the next step); "fast" and then the
    reference solver when ``solver`` fails (touching rigid particles can make the coarse
    matrix of an AMG hierarchy indefinite); the error message if all fail."""
    errors = []
    order = [solver] + [s for s in ("fast", "reference") if s != solver]
    for s in order:
        try:
            return homogenize_mesh(mesh, forces_N=forces, virial_stress_Pa=virial, matrix=matrix,
                                   rigid=True, tol=tol, solver=s, initial_guess=initial_guess,
                                   keep_solution=True)
        except (np.linalg.LinAlgError, RuntimeError, ValueError) as exc:
            errors.append(f"{s}: {exc}")
    return "cell FEM failed on the relaxed RVE (" + "; ".join(errors) + ")"


def _pair_contact_forces(x, a, box, g0, matrix, X_ref=None, stiffen=1.0):
    """(i, j, d_ij, force on i from j) of the contact penalty pairs (see :func:`_contact`)."""
    k_c = _contact_stiffness(a, matrix) * stiffen
    out = []
    i, j, d, r, g = _pairs(x, a, box, g0)
    ga = _activation_gap(X_ref, a, box, i, j, g0)
    for p, q, dv, rv, gv, g0p in zip(i, j, d, r, g, ga):
        if gv >= g0p:
            continue
        kc = 2.0 * k_c[p] * k_c[q] / (k_c[p] + k_c[q])
        phi, _ = _barrier(gv, g0p, kc)
        out.append((p, q, dv, phi * dv / rv))
    return out


def pair_contact_forces(centers_m, radii_m, box_m: float, gap_m: float, matrix: ElasticMaterial,
                        reference_centers_m=None, stiffen: float = 1.0) -> list:
    """The contact penalty of :func:`relax` between the particles at ``centers_m`` (radii
    ``radii_m``, periodic cube ``box_m``): a list of ``(i, j, d_ij, force on i from j [N])`` per
    pair closer than its activation gap (``gap_m``, or the pair's gap at ``reference_centers_m``
    if smaller), ``d_ij`` the minimum-image vector between them [m]; ``stiffen`` scales the
    penalty stiffness (50 x the sphere's elastic spring in ``matrix``). E.g. the contact share of
    a relaxed RVE's virial stress is ``-sum outer(d_ij, f_ij) / box_m^3``."""
    return _pair_contact_forces(centers_m, radii_m, box_m, gap_m, matrix, reference_centers_m,
                                stiffen)


def _contact_stiffness(a, matrix):
    """Penalty stiffness per particle [N/m]: 50 x the elastic spring 1/U0 of the sphere in the
    matrix. The dipole force at contact of saturated Fe spheres, ~0.5 mu0 Ms^2 a^2, displaces a
    sphere by up to ~3 radii against a 0.1 MPa matrix: 50 x stiffer keeps the overlap of the
    default g0 = 5 % of a radius below g0 (no interpenetration), and a constant stiffness keeps
    the Newton steps exact."""
    return 50.0 / rigid_sphere_displaceability(a, _shear(matrix), matrix.nu)


def magnetostriction_curve(rve, B_steps_T, *, law=DEFAULT_LAW, law_params=None,
                           matrix: ElasticMaterial = elastic(PDMS), voxels: int = 32,
                           demag_factor=None, direction=(0.0, 0.0, 1.0), **relax_kw) -> dict:
    """Free magnetostriction of an RVE along the field, relaxed and affine, against B.

    What a diagnosis cause (e.g. ``microstructure_evolution``) needs: for each field step the
    strain along the field of the relaxed RVE (:func:`relax`, ``boundary="free"``) and of the
    RVE with the particles as placed (same dipole solve and cell FEM, no relaxation), the
    magnetization along the field and the Young's modulus along the field of both.

    Returns
    -------
    dict of lists (one entry per step): ``B_T``, ``strain_relaxed``, ``strain_affine`` [-],
    ``M_eff_relaxed_A_per_m``, ``M_eff_affine_A_per_m`` [A/m], ``E_parallel_relaxed_Pa``,
    ``E_parallel_affine_Pa`` [Pa]; and ``result`` (the :class:`RelaxResult`).
    """
    n = np.asarray(direction, dtype=float)
    n = n / np.linalg.norm(n)
    res = relax(rve, B_steps_T, law=law, law_params=law_params, matrix=matrix, voxels=voxels,
                demag_factor=demag_factor, direction=n, **relax_kw)
    mesh = voxelize(rve, voxels)
    out = {k: [] for k in ("B_T", "strain_relaxed", "strain_affine", "M_eff_relaxed_A_per_m",
                           "M_eff_affine_A_per_m", "E_parallel_relaxed_Pa",
                           "E_parallel_affine_Pa")}
    guess = None       # the as-placed mesh is the same at every step: its strain solutions too
    for s in res.steps:
        st = solve_dipoles(rve, s["B_T"] * n, 0.0, law, demag_factor=demag_factor,
                           **dict(law_params or {}))
        aff = homogenize_mesh(mesh, forces_N=st.total_force_N,
                              virial_stress_Pa=st.virial_stress_Pa, matrix=matrix, rigid=True,
                              solver=relax_kw.get("cell_solver", "auto"),
                              initial_guess=guess,
                              keep_solution=relax_kw.get("cell_warm_start", True))
        guess = aff.solution
        out["B_T"].append(s["B_T"])
        out["strain_relaxed"].append(float(n @ np.asarray(s["strain_mag"]) @ n))
        out["strain_affine"].append(float(n @ np.asarray(aff.strain_mag) @ n))
        out["M_eff_relaxed_A_per_m"].append(s["M_eff_A_per_m"])
        out["M_eff_affine_A_per_m"].append(float(np.asarray(st.M_eff_A_per_m) @ n))
        out["E_parallel_relaxed_Pa"].append(s["E_eff_parallel_Pa"])
        out["E_parallel_affine_Pa"].append(_young_along(aff.C_eff_Pa, n))
    out["result"] = res
    return out
