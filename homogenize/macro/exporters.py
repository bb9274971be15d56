"""Exporters of homogenized parameters to external macro solvers, and parsers that read them back.

Snippets (:func:`to_elmer`, :func:`to_abaqus`, :func:`abaqus_model`, :func:`abaqus_step`)
---------------------------------------------------------------------------------------------
* Elmer (StressSolver): a ``Material`` section (``Youngs Modulus``, ``Poisson Ratio``,
  ``Density``) and a ``Body Force`` section with ``Stress Bodyforce 1..3`` -- force per volume
  [N/m^3]. Elmer has no separate gravity load for this solver, so self-weight (if asked for) is
  added to the body force and both parts are named in comments.
* Abaqus / CalculiX (input-file keywords), in two parts as the input-file grammar requires:
  model data (:func:`abaqus_model`: ``*MATERIAL`` with ``*ELASTIC`` (E, nu) and ``*DENSITY``)
  and step data (:func:`abaqus_step`: ``*DLOAD`` with the body-force labels ``BX/BY/BZ``
  [N/m^3] on an element set, plus an optional ``GRAV`` line, magnitude [m/s^2] and direction,
  for the self-weight). Each part can be ``*INCLUDE``-d where it belongs (the model part
  among the model data, the step part between ``*STEP`` and ``*END STEP``).
  :func:`to_abaqus` gives both: the model part, then a complete ``*STEP, *STATIC ... *END STEP``
  block, so the text is valid at the end of the model data of a deck that defines the element
  set and a ``*SOLID SECTION`` (and a ``*BOUNDARY``).

Complete decks (:func:`write_deck`)
-----------------------------------
A runnable input for the two macro problems of :mod:`homogenize.macro`, on the meshes their own
solvers use (:func:`homogenize.macro.fem.box_mesh` of the same tensor grids):

* ``kind="cantilever"``: the strip ``[0, L] x [0, w] x [0, t]`` (full width), clamped
  (``u = 0``) on ``x = 0``; node set ``NTIP`` = the tip centre ``(L, w/2, t/2)``;
* ``kind="channel"``: the quarter block of :func:`homogenize.macro.channel.solve_channel`
  (channel cut out), ``u = 0`` on the glass ``z = 0``, mirror planes ``u_x = 0`` at
  ``x = d/2`` and ``u_y = 0`` at ``y = W/2``; ``NTIP`` = the centre of the ceiling's underside
  ``(d/2, W/2, b)``.

``solver="abaqus"`` (also read by CalculiX ``ccx``) writes one ``.inp``: ``*NODE``,
``*ELEMENT`` (``C3D10``: the tetrahedra of :func:`box_mesh` with their edge midpoints, the
same P2 space as ``solve_cantilever(..., order=2)``; or ``C3D20R``: the hexahedra of the same
grid; for the cantilever also ``C3D20``, ``C3D4``, ``C3D8``, ``C3D8R``, ``C3D8I``, see
:data:`ABAQUS_ELEMENTS`), ``*NSET``/``*ELSET``, ``*SOLID SECTION``, the material,
``*BOUNDARY``, then ``*STEP``,
``*STATIC``, ``*DLOAD`` (``BX/BY/BZ`` and ``GRAV``), ``*NODE FILE`` U, ``*NODE PRINT`` U of
``NTIP``, ``*END STEP``. :func:`parse_ccx_dat` reads the printed displacements back.

Default cantilever deck and its accuracy: ``C3D20R`` (:data:`DECK_ELEMENT`; serendipity hexahedra
with reduced integration, which do not shear-lock in bending) on
``beam_divisions(strip, DECK_NZ=2, DECK_ASPECT=1)``, (39, 10, 2) for the seed strip
(19.369 x 5 x 1 mm, E = 2 MPa, nu = 0.45) at 40 kN/m^3. Converged linear tip: 3.998 mm, from a
CalculiX refinement study of this deck, C3D20R on (20, 4, 2) x 2^k, k = 0..2: 3.9385, 3.9859,
3.9954 mm (rate 2.3, Richardson 3.9977 mm), then (160, 16, 8): 3.9970 mm (0.04 % from
(80, 16, 8)); independently mapsim's P2 FEM (:mod:`homogenize.macro.convergence`, (31, 4, 2) /
(62, 8, 4) half width, Richardson): 3.9970 mm. The default deck, linear: 3.9720 mm, -0.65 %. The
former default, C3D10 on (13, 4, 2), gave 3.814 mm (-4.6 %; C3D8I on that grid 3.818 mm): too
few elements along the strip for the clamped root's edge singularity, which sets the rate of
convergence. With NLGEOM (written by the rule below at this load): 3.8414 mm against the
converged 3.866 mm (the linear 3.998 mm times the nonlinear/linear ratio: CalculiX 0.9671 on
(39, 10, 2), 0.9670 on (40, 8, 4); mapsim's neo-Hookean P2, :func:`~homogenize.macro.fem.
neo_hookean_solve`, 0.9675 on (40, 4, 2)): -0.64 %.

Geometric nonlinearity (``nlgeom``): "auto" writes ``*STEP, NLGEOM`` when the linear estimate of
the deflection (:func:`linear_deflection_estimate_m`: Euler-Bernoulli tip of the strip, or the
channel ceiling as a clamped plate strip) exceeds :data:`NLGEOM_FRACTION` = 0.1 of the thickness
(``t``, or the ceiling's ``c``): there a clamped plate's membrane stiffening reaches ~0.75 %
(``0.75 (w/t)^2``, one-term Galerkin with immovable edges); for the cantilever the rule is
conservative (its nonlinearity grows as (deflection/length)^2). The step then starts at 25 % of
the load with automatic increments.

A varying load (``body_force``, e.g. a magnet's :func:`magnet_body_force`): evaluated at each
element's centroid of the undeformed strip and written per element, ``e, BX|BY|BZ, value``
[N/m^3]; a dead load (no follower field, no pull-in: ``mapsim beam --gap-m`` takes the field on
the deformed strip), stated in the deck's comments. The sum of load x volume equals the force on
the strip to the centroid rule's O(h^2) error (2.3e-3 relative on the default mesh for a
cylinder magnet 10 mm below the tip).

``solver="elmer"`` writes ``<out>.sif`` and the mesh directory ``<out dir>/<stem>_mesh`` in
ElmerGrid's format (``mesh.header``, ``mesh.nodes``, ``mesh.elements`` with quadratic
tetrahedra, type 510, ``mesh.boundary`` with quadratic triangles, type 306, on the boundaries
that carry conditions). The ``.sif`` uses the documented keywords of ElmerSolver's
StressSolver, ResultOutputSolver and SaveScalars (:data:`ELMER_KEYWORDS`); it is checked
against those keywords (:func:`parse_sif`), not run (ElmerSolver is not installed here).

Everything is SI. :func:`parse_elmer` and :func:`parse_abaqus` return an :class:`ExportSpec`-like
dict of the numbers, so a round trip is checkable.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass

import numpy as np

from micro.common.validate import InputError, check_choice, check_positive, check_range

__all__ = ["ExportSpec", "DIRECTIONS", "to_elmer", "to_abaqus", "abaqus_model", "abaqus_step",
           "parse_elmer", "parse_abaqus", "export_text", "Deck", "DeckMesh", "deck_mesh",
           "write_deck", "parse_ccx_dat", "parse_sif", "read_elmer_mesh", "ELMER_KEYWORDS",
           "DECK_KINDS", "DECK_SOLVERS", "ABAQUS_ELEMENTS", "LINEAR_ELEMENTS", "DECK_ELEMENT",
           "DECK_NZ", "DECK_ASPECT", "NLGEOM_MODES", "NLGEOM_FRACTION", "magnet_body_force",
           "linear_deflection_estimate_m", "element_centroids_volumes"]

#: allowed force directions (unit vectors along the global axes)
DIRECTIONS = {"+x": (1, 0, 0), "-x": (-1, 0, 0), "+y": (0, 1, 0), "-y": (0, -1, 0),
              "+z": (0, 0, 1), "-z": (0, 0, -1)}


@dataclass(frozen=True)
class ExportSpec:
    """What is exported.

    body_force_N_m3 : magnitude of the magnetic body force [N/m^3], >= 0
    E_Pa : Young's modulus [Pa]; nu : Poisson ratio in (-1, 0.5); density_kg_m3 : [kg/m^3]
    direction : one of :data:`DIRECTIONS` -- direction of the body force (and of gravity)
    gravity_m_s2 : self-weight acceleration [m/s^2], 0 for none
    name : material name; elset : Abaqus element set; index : Elmer section number
    """
    body_force_N_m3: float
    E_Pa: float
    nu: float
    density_kg_m3: float
    direction: str = "-z"
    gravity_m_s2: float = 0.0
    name: str = "MAP_PDMS"
    elset: str = "EALL"
    index: int = 1

    def __post_init__(self):
        check_positive("body_force_N_m3", self.body_force_N_m3, "N/m^3", allow_zero=True)
        check_positive("E_Pa", self.E_Pa, "Pa")
        check_range("nu", self.nu, -1.0, 0.5, "", lo_open=True, hi_open=True)
        check_positive("density_kg_m3", self.density_kg_m3, "kg/m^3", allow_zero=True)
        check_choice("direction", self.direction, tuple(DIRECTIONS))
        check_positive("gravity_m_s2", self.gravity_m_s2, "m/s^2", allow_zero=True)
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_\-]*", self.name):
            raise InputError(f"name must start with a letter and contain only letters, digits, "
                             f"'_' or '-', got {self.name!r}")
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_\-]*", self.elset):
            raise InputError(f"elset must be an Abaqus set name (letters, digits, '_', '-'), "
                             f"got {self.elset!r}")
        check_positive("index", self.index, "")

    @property
    def unit(self) -> np.ndarray:
        return np.array(DIRECTIONS[self.direction], float)


def _g(x: float) -> str:
    return repr(float(x))  # shortest exact round-trip representation


def to_elmer(spec: ExportSpec) -> str:
    """Elmer ``.sif`` Material and Body Force sections for ``spec``."""
    weight = spec.density_kg_m3 * spec.gravity_m_s2
    total = (spec.body_force_N_m3 + weight) * spec.unit
    lines = [
        "! mapsim export for Elmer StressSolver (SI units: Pa, kg/m^3, N/m^3)",
        f"! magnetic body force {_g(spec.body_force_N_m3)} N/m^3 along {spec.direction}"
        + (f", plus self-weight density*g = {_g(weight)} N/m^3" if weight else ""),
        f"Material {spec.index}",
        f'  Name = "{spec.name}"',
        f"  Youngs Modulus = Real {_g(spec.E_Pa)}",
        f"  Poisson Ratio = Real {_g(spec.nu)}",
        f"  Density = Real {_g(spec.density_kg_m3)}",
        "End",
        "",
        f"Body Force {spec.index}",
        f'  Name = "{spec.name}_magnetic"',
    ]
    lines += [f"  Stress Bodyforce {i + 1} = Real {_g(total[i] + 0.0)}" for i in range(3)]
    lines += ["End", ""]
    return "\n".join(lines)


def abaqus_model(spec: ExportSpec) -> str:
    """Abaqus model data for ``spec``: ``*MATERIAL`` with ``*ELASTIC`` and ``*DENSITY``."""
    return "\n".join([
        "** mapsim export for Abaqus / CalculiX, model data (SI units: Pa, kg/m^3)",
        f"*MATERIAL, NAME={spec.name}",
        "*ELASTIC",
        f"{_g(spec.E_Pa)}, {_g(spec.nu)}",
        "*DENSITY",
        f"{_g(spec.density_kg_m3)},",
    ]) + "\n"


def abaqus_step(spec: ExportSpec) -> str:
    """Abaqus step data for ``spec`` (between ``*STEP`` and ``*END STEP``): ``*DLOAD`` with the
    magnetic body force ``B<axis>`` [N/m^3] and, if ``gravity_m_s2 > 0``, ``GRAV``."""
    u = spec.unit
    axis = "XYZ"[int(np.argmax(np.abs(u)))]
    lines = [
        "** mapsim export for Abaqus / CalculiX, step data (SI units: N/m^3, m/s^2)",
        "** magnetic body force per volume" + (" and self-weight" if spec.gravity_m_s2 > 0 else ""),
        "*DLOAD",
        f"{spec.elset}, B{axis}, {_g(spec.body_force_N_m3 * u.sum())}",
    ]
    if spec.gravity_m_s2 > 0:
        lines.append(f"{spec.elset}, GRAV, {_g(spec.gravity_m_s2)}, "
                     + ", ".join(_g(c + 0.0) for c in u))
    return "\n".join(lines) + "\n"


def to_abaqus(spec: ExportSpec) -> str:
    """Abaqus model data (:func:`abaqus_model`) followed by a complete static step holding the
    loads (:func:`abaqus_step`): valid at the end of a deck's model data."""
    return (abaqus_model(spec) + "** the loads, in a static step\n*STEP\n*STATIC\n"
            + abaqus_step(spec) + "*END STEP\n")


def export_text(spec: ExportSpec, to: str) -> str:
    """``to_elmer`` or ``to_abaqus`` by name ("elmer" | "abaqus")."""
    check_choice("to", to, ("elmer", "abaqus"))
    return to_elmer(spec) if to == "elmer" else to_abaqus(spec)


_NUM = r"([-+0-9.eEinfa]+)"


def _num(text: str, pattern: str, what: str) -> float:
    m = re.search(pattern, text, flags=re.IGNORECASE | re.MULTILINE)
    if not m:
        raise InputError(f"{what} not found in the exported text")
    return float(m.group(1))


def parse_elmer(text: str) -> dict:
    """Numbers of an Elmer snippet written by :func:`to_elmer`.

    Returns {E_Pa, nu, density_kg_m3, body_force_N_m3 (3,)} -- the total body force vector.
    """
    E = _num(text, r"^\s*Youngs Modulus\s*=\s*(?:Real\s+)?" + _NUM, "Youngs Modulus")
    nu = _num(text, r"^\s*Poisson Ratio\s*=\s*(?:Real\s+)?" + _NUM, "Poisson Ratio")
    rho = _num(text, r"^\s*Density\s*=\s*(?:Real\s+)?" + _NUM, "Density")
    f = np.zeros(3)
    for i in range(3):
        pat = rf"^\s*Stress Bodyforce {i + 1}\s*=\s*(?:Real\s+)?" + _NUM
        if re.search(pat, text, flags=re.IGNORECASE | re.MULTILINE):
            f[i] = _num(text, pat, f"Stress Bodyforce {i + 1}")
    return {"E_Pa": E, "nu": nu, "density_kg_m3": rho, "body_force_N_m3": f}


def parse_abaqus(text: str) -> dict:
    """Numbers of an Abaqus snippet written by :func:`to_abaqus`.

    Returns {E_Pa, nu, density_kg_m3, body_force_N_m3 (3,), gravity_m_s2, gravity_direction (3,)}.
    """
    m = re.search(r"^\*ELASTIC[^\n]*\n\s*" + _NUM + r"\s*,\s*" + _NUM, text,
                  flags=re.IGNORECASE | re.MULTILINE)
    if not m:
        raise InputError("*ELASTIC data line not found in the exported text")
    E, nu = float(m.group(1)), float(m.group(2))
    rho = _num(text, r"^\*DENSITY[^\n]*\n\s*" + _NUM, "*DENSITY data line")
    f = np.zeros(3)
    for k, axis in enumerate("XYZ"):
        pat = rf"^[^*\n][^,\n]*,\s*B{axis}\s*,\s*" + _NUM
        if re.search(pat, text, flags=re.IGNORECASE | re.MULTILINE):
            f[k] = _num(text, pat, f"B{axis} load")
    grav = re.search(r"^[^*\n][^,\n]*,\s*GRAV\s*,\s*" + ",\\s*".join([_NUM] * 4), text,
                     flags=re.IGNORECASE | re.MULTILINE)
    g = float(grav.group(1)) if grav else 0.0
    gdir = np.array([float(grav.group(i)) for i in (2, 3, 4)]) if grav else np.zeros(3)
    return {"E_Pa": E, "nu": nu, "density_kg_m3": rho, "body_force_N_m3": f,
            "gravity_m_s2": g, "gravity_direction": gdir}


# ============================================================================ complete decks
#: problems :func:`write_deck` writes
DECK_KINDS = ("cantilever", "channel")
#: target solvers of :func:`write_deck`
DECK_SOLVERS = ("abaqus", "elmer")
#: element types of Abaqus/CalculiX decks: quadratic tetrahedra and serendipity hexahedra
#: (reduced or full integration), and, for the cantilever only, linear tetrahedra and trilinear
#: hexahedra (full ``C3D8``, reduced with hourglass control ``C3D8R``, incompatible modes
#: ``C3D8I``) -- the element-sensitivity study of :mod:`homogenize.macro.elements`
ABAQUS_ELEMENTS = ("C3D10", "C3D20R", "C3D4", "C3D8", "C3D8R", "C3D8I", "C3D20")
#: the linear (corner-node only) element types among :data:`ABAQUS_ELEMENTS`
LINEAR_ELEMENTS = ("C3D4", "C3D8", "C3D8R", "C3D8I")
#: default element of an Abaqus/CalculiX cantilever deck (the channel's is ``C3D10``, Elmer's
#: quadratic tetrahedra): serendipity hexahedra with reduced integration, free of shear locking
DECK_ELEMENT = "C3D20R"
#: default layers through the strip and element aspect of a deck: :func:`beam_divisions`
#: ``(strip, DECK_NZ, DECK_ASPECT)``, (39, 10, 2) for the seed strip (module docstring)
DECK_NZ = 2
DECK_ASPECT = 1.0
#: ``nlgeom`` modes of :func:`write_deck`
NLGEOM_MODES = ("auto", "on", "off")
#: ``nlgeom="auto"``: the step carries NLGEOM when the linear estimate of the deflection exceeds
#: this fraction of the thickness (the strip's ``t``, the channel ceiling's ``c``)
NLGEOM_FRACTION = 0.1

# corner pairs of the edge nodes, in Abaqus (= Elmer 510 / 306) node order
_TET10_EDGES = ((0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3))
_TRI6_EDGES = ((0, 1), (1, 2), (2, 0))
_HEX20_EDGES = ((0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4),
                (0, 4), (1, 5), (2, 6), (3, 7))
# faces of a tetrahedron (corner indices), each opposite one corner
_TET_FACES = ((0, 1, 2), (0, 1, 3), (1, 2, 3), (0, 2, 3))


@dataclass(frozen=True)
class DeckMesh:
    """A quadratic mesh ready for writing (0-based indices).

    nodes_m : (N, 3) coordinates [m]; elements : (E, 10) tetrahedra (C3D10 / Elmer 510 node
    order), (E, 20) hexahedra (C3D20 order), or for the linear types (E, 4) tetrahedra / (E, 8)
    hexahedra; element : one of :data:`ABAQUS_ELEMENTS`;
    node_sets : name -> node indices; boundaries : name -> (F, 6) quadratic triangles with
    (F,) parent elements, as ``(faces, parents)`` (tetrahedral meshes only);
    fixed : (node set, tuple of fixed components 1..3) pairs; tip_m : (3,) the probed point;
    divisions : the hexahedra per direction of the tensor grid.

    ``node_sets["NTIP"]`` is the node at ``tip_m``; for linear elements on a grid with an odd
    number of layers (no node at mid-thickness) it is the nodes of the tip line
    ``x = L, y = w/2``, sorted by ``z``, between which the displacement is linear.
    """
    nodes_m: np.ndarray
    elements: np.ndarray
    element: str
    node_sets: dict
    boundaries: dict
    fixed: tuple
    tip_m: np.ndarray
    divisions: tuple

    @property
    def tip_node(self) -> int:
        return int(self.node_sets["NTIP"][0])


@dataclass(frozen=True)
class Deck:
    """What :func:`write_deck` wrote: ``files`` (the input deck first), the mesh, the spec;
    ``nlgeom`` whether the step carries NLGEOM, ``estimate_m`` the linear deflection estimate
    the ``auto`` rule used [m]; with a varying load ``element_loads_N_m3`` (E, 3) the body
    force written per element [N/m^3] and ``element_volumes_m3`` (E,) [m^3]."""
    kind: str
    solver: str
    files: tuple
    mesh: DeckMesh
    spec: ExportSpec
    nlgeom: bool = False
    estimate_m: float = float("nan")
    element_loads_N_m3: np.ndarray | None = None
    element_volumes_m3: np.ndarray | None = None

    @property
    def path(self):
        return self.files[0]


def _with_midside(corners: np.ndarray, cells: np.ndarray, edges) -> tuple[np.ndarray, np.ndarray]:
    """Append a node at the midpoint of every listed edge of ``cells`` (shared edges once)."""
    pairs = np.stack([np.sort(cells[:, list(e)], axis=1) for e in edges], axis=1)  # (E, k, 2)
    flat = pairs.reshape(-1, 2)
    uniq, inv = np.unique(flat, axis=0, return_inverse=True)
    mids = 0.5 * (corners[uniq[:, 0]] + corners[uniq[:, 1]])
    nodes = np.vstack([corners, mids])
    extra = len(corners) + inv.reshape(len(cells), len(edges))
    return nodes, np.hstack([cells, extra])


def _positive_tets(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Reorder corners so that every tetrahedron has positive volume (Abaqus convention)."""
    t = t.copy()
    a, b, c, d = (p[t[:, k]] for k in range(4))
    neg = np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) < 0
    t[neg, 0], t[neg, 1] = t[neg, 1], t[neg, 0].copy()
    return t


def _compact(p: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    used = np.unique(t)
    new = np.full(len(p), -1, dtype=np.int64)
    new[used] = np.arange(len(used))
    return p[used], new[t]


def _on(nodes, axis, value, tol):
    return np.nonzero(np.abs(nodes[:, axis] - value) < tol)[0]


def _tip_set(nodes, point, tol, hint):
    d = np.linalg.norm(nodes - point, axis=1)
    k = int(np.argmin(d))
    if d[k] > tol:
        raise InputError(f"no mesh node at the probed point {tuple(float(x) for x in point)} m "
                         f"(nearest {d[k]:.3g} m away): {hint}")
    return np.array([k])


def _boundary_faces(t10: np.ndarray, nodes: np.ndarray, axis: int, value: float, tol: float):
    """Quadratic triangles (Elmer 306 order) of the tetrahedron faces on the plane
    ``x[axis] = value``, with their parent elements."""
    faces, parents = [], []
    corner_on = np.abs(nodes[t10[:, :4], axis] - value) < tol          # (E, 4)
    for f in _TET_FACES:
        hit = np.nonzero(corner_on[:, list(f)].all(axis=1))[0]
        for e in hit:
            tri = t10[e, list(f)]
            mids = []
            for a, b in _TRI6_EDGES:
                pair = {f[a], f[b]}
                k = next(i for i, ed in enumerate(_TET10_EDGES) if set(ed) == pair)
                mids.append(t10[e, 4 + k])
            faces.append(np.concatenate([tri, mids]))
            parents.append(e)
    return np.array(faces, dtype=np.int64).reshape(-1, 6), np.array(parents, dtype=np.int64)


def _hex20(xs, ys, zs) -> tuple[np.ndarray, np.ndarray]:
    """Serendipity hexahedra (C3D20 node order) on the tensor grid ``xs x ys x zs``."""
    nx, ny, nz = len(xs) - 1, len(ys) - 1, len(zs) - 1
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    corners = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    vid = lambda i, j, k: (i * (ny + 1) + j) * (nz + 1) + k  # noqa: E731
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz),
                                              indexing="ij"))
    cells = np.stack([vid(i, j, k), vid(i + 1, j, k), vid(i + 1, j + 1, k), vid(i, j + 1, k),
                      vid(i, j, k + 1), vid(i + 1, j, k + 1), vid(i + 1, j + 1, k + 1),
                      vid(i, j + 1, k + 1)], axis=1)
    return _with_midside(corners, cells, _HEX20_EDGES)


def deck_mesh(kind: str, geometry, *, element: str = "C3D10", divisions=None, nz: int = 2,
              aspect: float = 3.0, nc: int = 2, channel_aspect: float = 4.0) -> DeckMesh:
    """The quadratic mesh of a deck (see the module docstring).

    Parameters
    ----------
    kind : "cantilever" | "channel"
    geometry : :class:`~homogenize.macro.cantilever.Strip` or
        :class:`~homogenize.macro.channel.ChannelGeometry` [m]
    element : "C3D10" (tetrahedra of :func:`~homogenize.macro.fem.box_mesh`, the mesh of
        ``solve_cantilever(..., half=False, divisions=...)`` and of ``solve_channel``) or
        "C3D20R" (hexahedra of the same tensor grid; cantilever only); cantilever only also
        "C3D20" (same nodes, full integration), "C3D4" (the box_mesh tetrahedra without edge
        nodes) and "C3D8", "C3D8R", "C3D8I" (the grid's hexahedra, corner nodes)
    divisions : (nx, ny, nz) hexahedra along length, full width, thickness (cantilever); None:
        :func:`~homogenize.macro.cantilever.beam_divisions` ``(strip, nz, aspect)``
    nc, channel_aspect : layers through the ceiling and aspect of the channel mesh (as in
        ``solve_channel(nc=..., aspect=...)``)
    """
    check_choice("kind", kind, DECK_KINDS)
    check_choice("element", element, ABAQUS_ELEMENTS)
    from homogenize.macro.fem import box_mesh
    if kind == "cantilever":
        from homogenize.macro.cantilever import Strip, beam_divisions
        if not isinstance(geometry, Strip):
            raise InputError(f"kind='cantilever' needs a Strip geometry, got "
                             f"{type(geometry).__name__}")
        L, w, t = geometry.length_m, geometry.width_m, geometry.thickness_m
        div = beam_divisions(geometry, nz, aspect) if divisions is None else \
            tuple(int(d) for d in divisions)
        if len(div) != 3 or min(div) < 1:
            raise InputError(f"divisions must be three positive integers (nx, ny, nz), got "
                             f"{divisions!r}")
        xs, ys, zs = (np.linspace(0.0, a, n + 1) for a, n in zip((L, w, t), div))
        tol = 1e-9 * L
        if element == "C3D10":
            m = box_mesh(xs, ys, zs)
            p, cells = m.p.T.copy(), _positive_tets(m.p.T, m.t.T.astype(np.int64))
            nodes, elems = _with_midside(p, cells, _TET10_EDGES)
            bnd = {"ROOT": _boundary_faces(elems, nodes, 0, 0.0, tol)}
        elif element == "C3D4":
            m = box_mesh(xs, ys, zs)
            nodes = m.p.T.copy()
            elems = _positive_tets(nodes, m.t.T.astype(np.int64))
            bnd = {}
        else:
            nodes, elems = _hex20(xs, ys, zs)
            if element in LINEAR_ELEMENTS:
                # the corner nodes come first (C3D8 order = the first 8 of C3D20)
                nodes, elems = _compact(nodes, elems[:, :8])
            bnd = {}
        tip = np.array([L, w / 2, t / 2])
        if element in LINEAR_ELEMENTS and not np.any(np.linalg.norm(nodes - tip, axis=1) < tol):
            # odd number of layers: the tip line's nodes, the tip value is interpolated
            line = np.nonzero((np.abs(nodes[:, 0] - L) < tol)
                              & (np.abs(nodes[:, 1] - w / 2) < tol))[0]
            if line.size == 0:
                raise InputError("no mesh node on the tip line (L, w/2, z): use an even ny")
            ntip = line[np.argsort(nodes[line, 2])]
        else:
            ntip = _tip_set(nodes, tip, tol, "use an even ny, or quadratic elements")
        sets = {"NROOT": _on(nodes, 0, 0.0, tol), "NTIP": ntip}
        return DeckMesh(nodes, elems, element, sets, bnd, (("NROOT", (1, 2, 3)),), tip, div)
    from homogenize.macro import channel as ch
    if not isinstance(geometry, ch.ChannelGeometry):
        raise InputError(f"kind='channel' needs a ChannelGeometry, got {type(geometry).__name__}")
    if element != "C3D10":
        raise InputError(f"element {element!r}: the channel deck is written with C3D10 only "
                         f"(the block with the channel cut out is meshed with tetrahedra)")
    g = geometry
    a, b, c, d, s = g.a_m, g.b_m, g.c_m, g.d_m, g.wall
    nc = int(check_positive("nc", nc, ""))
    # the mesh of solve_channel: same divisions, grading and removed channel elements
    nd, nw, na, nb, nc = ch._divisions(g, nc, channel_aspect)
    xs = ch._graded(0.0, d / 2, nd, ratio=2.0)
    ys = np.concatenate((ch._graded(0.0, s, nw, ratio=0.25)[:-1],
                         np.linspace(s, s + a / 2, na + 1)))
    zs = np.concatenate((np.linspace(0.0, b, nb + 1)[:-1], np.linspace(b, b + c, nc + 1)))
    m = box_mesh(xs, ys, zs)
    mid = m.p[:, m.t].mean(axis=1)
    keep = ~((mid[1] > s) & (mid[2] < b))
    p, cells = _compact(m.p.T.copy(), m.t.T[keep].astype(np.int64))
    cells = _positive_tets(p, cells)
    nodes, elems = _with_midside(p, cells, _TET10_EDGES)
    tol = 1e-9 * max(a, b, c, d)
    ymax = s + a / 2
    tip = np.array([d / 2, ymax, b])
    sets = {"NBOTTOM": _on(nodes, 2, 0.0, tol), "NSYMX": _on(nodes, 0, d / 2, tol),
            "NSYMY": _on(nodes, 1, ymax, tol), "NTIP": _tip_set(nodes, tip, tol, "")}
    bnd = {"BOTTOM": _boundary_faces(elems, nodes, 2, 0.0, tol),
           "SYMX": _boundary_faces(elems, nodes, 0, d / 2, tol),
           "SYMY": _boundary_faces(elems, nodes, 1, ymax, tol)}
    fixed = (("NBOTTOM", (1, 2, 3)), ("NSYMX", (1,)), ("NSYMY", (2,)))
    return DeckMesh(nodes, elems, "C3D10", sets, bnd, fixed, tip, (nd, nw + na, nb + nc))


def element_centroids_volumes(mesh: DeckMesh) -> tuple[np.ndarray, np.ndarray]:
    """Centroids (E, 3) [m] and volumes (E,) [m^3] of the deck's elements (straight-edged
    tetrahedra, or the axis-parallel boxes of the hexahedral grid)."""
    X = mesh.nodes_m
    if mesh.elements.shape[1] in (4, 10):
        c = [X[mesh.elements[:, k]] for k in range(4)]
        vol = np.abs(np.einsum("ij,ij->i", np.cross(c[1] - c[0], c[2] - c[0]), c[3] - c[0])) / 6
        return sum(c) / 4.0, vol
    c = X[mesh.elements[:, :8]]                                  # (E, 8, 3) corners
    return c.mean(axis=1), np.prod(c.max(axis=1) - c.min(axis=1), axis=1)


def linear_deflection_estimate_m(kind: str, spec: ExportSpec, geometry,
                                 element_loads_N_m3=None, mesh: DeckMesh | None = None) -> float:
    """The project's linear estimate of the largest deflection [m] (the NLGEOM rule's input).

    cantilever: Euler-Bernoulli tip deflection under the body force plus self-weight
    (:func:`~homogenize.macro.closed_form.eb_tip_deflection_m`); with per-element loads their
    z component averaged over each column of elements along the length (a uniform force is
    taken as transverse whatever its direction: conservative). channel: the
    ceiling as a plate strip clamped on both walls,
    :func:`~homogenize.macro.closed_form.plate_clamped_strip_deflection_m` (span a, thickness c).
    """
    from homogenize.macro import closed_form as cf
    weight = spec.density_kg_m3 * spec.gravity_m_s2
    if kind == "channel":
        g = geometry
        return abs(cf.plate_clamped_strip_deflection_m(spec.body_force_N_m3 + weight, g.a_m,
                                                       g.c_m, spec.E_Pa, spec.nu))
    L, w, t = geometry.length_m, geometry.width_m, geometry.thickness_m
    if element_loads_N_m3 is None:
        return abs(cf.eb_tip_deflection_m(spec.body_force_N_m3 + weight, L, w, t, spec.E_Pa))
    cen, vol = element_centroids_volumes(mesh)
    xs = np.round(cen[:, 0] / L, 9)
    cols = np.unique(xs)
    # the transverse load per unit length of each column, as a force per strip volume
    fz = np.array([-(element_loads_N_m3[xs == x, 2] * vol[xs == x]).sum() for x in cols])
    fz = fz / np.array([vol[xs == x].sum() for x in cols])
    x = np.concatenate(([0.0], cols * L, [L]))
    prof = cf.BodyForceProfile(x, np.concatenate(([fz[0]], fz, [fz[-1]])) + weight)
    return abs(cf.eb_tip_deflection_m(prof, L, w, t, spec.E_Pa))


def magnet_body_force(source, M_of_H, demag_factor: float = 0.0):
    """``f(points_m (n, 3)) -> (n, 3)`` [N/m^3]: the magnetic body force of ``source`` at
    points of the undeformed strip, ``f = (M . grad) B = M_eff(H_in) grad |B_a|`` (``M`` along
    the applied field, curl-free outside the source), ``H_in = |B_a| / mu0 - N M`` with the
    demagnetizing factor ``N`` -- the law of :func:`homogenize.macro.magnets.body_force_along_strip`
    at single points instead of cross-section averages."""
    from scipy.constants import mu_0
    from homogenize.macro.magnets import _call_M, _internal_field, sample_field
    N = check_range("demag_factor", demag_factor, 0.0, 1.0, "")

    def f(points_m):
        B, grad = sample_field(source, np.asarray(points_m, float).reshape(-1, 3))
        Ha = np.linalg.norm(B, axis=1) / mu_0
        M = _call_M(M_of_H, _internal_field(M_of_H, Ha, N))
        return M[:, None] * grad
    return f


def _id_lines(ids_1based, per_line: int = 16) -> list[str]:
    ids = [str(int(i)) for i in ids_1based]
    return [", ".join(ids[k:k + per_line]) + ("," if k + per_line < len(ids) else "")
            for k in range(0, len(ids), per_line)]


def _abaqus_deck(kind: str, spec: ExportSpec, mesh: DeckMesh, *, nlgeom: bool = False,
                 estimate_m: float = float("nan"), element_loads=None,
                 notes: tuple = ()) -> str:
    out = [f"** mapsim {kind} deck for Abaqus / CalculiX (SI units: m, Pa, kg/m^3, N/m^3)"]
    out += [f"** {n}" for n in notes]
    out += ["*HEADING",
            f"mapsim {kind}: {mesh.element}, {len(mesh.nodes_m)} nodes, {len(mesh.elements)} "
            f"elements, tip node {mesh.tip_node + 1}",
            "*NODE, NSET=NALL"]
    # 14 significant digits: CalculiX reads at most 20 characters per number
    out += [f"{k + 1}, {x:.13e}, {y:.13e}, {z:.13e}" for k, (x, y, z) in enumerate(mesh.nodes_m)]
    out.append(f"*ELEMENT, TYPE={mesh.element}, ELSET={spec.elset}")
    for e, conn in enumerate(mesh.elements):
        # at most 16 entries per data line; a trailing comma continues the line
        out += _id_lines(np.concatenate(([e + 1], conn + 1)), 16)
    for name, idx in mesh.node_sets.items():
        out.append(f"*NSET, NSET={name}")
        out += _id_lines(np.sort(idx) + 1)
    out.append(f"*SOLID SECTION, ELSET={spec.elset}, MATERIAL={spec.name}")
    out.append("")             # the (empty) section data line
    out += abaqus_model(spec).rstrip("\n").split("\n")
    out.append("*BOUNDARY")
    for name, comps in mesh.fixed:
        out += [f"{name}, {c}, {c}" for c in comps]
    thick = "c" if kind == "channel" else "t"
    rule = (f"linear estimate of the deflection {estimate_m:.4g} m, NLGEOM above "
            f"{NLGEOM_FRACTION:g} {thick}")
    if nlgeom:
        # geometric nonlinearity; first increment 25 % of the load, then automatic increments
        # (cut back when Newton fails; converges for the seed strip up to 4e5 N/m^3, a 15 mm tip
        # deflection on the 19.4 mm strip)
        out += [f"** geometrically nonlinear step ({rule})", "*STEP, NLGEOM", "*STATIC",
                "0.25, 1.0, 1e-05, 1.0"]
    else:
        out += [f"** geometrically linear step ({rule})", "*STEP", "*STATIC"]
    if element_loads is None:
        out += abaqus_step(spec).rstrip("\n").split("\n")
    else:
        out += ["** magnetic body force per element [N/m^3], f = (M . grad) B at each element's "
                "centroid of the UNDEFORMED strip:",
                "** a dead load (no follower field, no pull-in); for the field on the deformed "
                "strip use mapsim beam --gap-m", "*DLOAD"]
        for e, fe in enumerate(element_loads):
            out += [f"{e + 1}, B{a}, {_g(fe[k] + 0.0)}" for k, a in enumerate("XYZ")]
        if spec.gravity_m_s2 > 0:
            out.append(f"{spec.elset}, GRAV, {_g(spec.gravity_m_s2)}, "
                       + ", ".join(_g(c + 0.0) for c in spec.unit))
    out += ["*NODE FILE", "U", "*NODE PRINT, NSET=NTIP", "U", "*END STEP"]
    return "\n".join(out) + "\n"


#: keywords of the Elmer ``.sif`` written by :func:`write_deck`, per section, as documented in
#: the Elmer Solver Manual and Elmer Models Manual (StressSolver, ResultOutputSolver,
#: SaveScalars). Values are the keyword names; ``parse_sif`` checks against them.
ELMER_KEYWORDS = {
    "Header": {"CHECK KEYWORDS", "Mesh DB", "Results Directory"},
    "Simulation": {"Max Output Level", "Coordinate System", "Simulation Type",
                   "Steady State Max Iterations", "Output Intervals"},
    "Constants": {"Gravity"},
    "Body": {"Target Bodies", "Name", "Equation", "Material", "Body Force"},
    "Solver": {"Equation", "Procedure", "Variable", "Exec Solver", "Linear System Solver",
               "Linear System Direct Method", "Steady State Convergence Tolerance",
               "Output File Name", "Vtu Format", "Filename", "Save Coordinates",
               "Calculate Stresses"},
    "Equation": {"Name", "Active Solvers"},
    "Material": {"Name", "Youngs Modulus", "Poisson Ratio", "Density"},
    "Body Force": {"Name", "Stress Bodyforce 1", "Stress Bodyforce 2", "Stress Bodyforce 3"},
    "Boundary Condition": {"Name", "Target Boundaries", "Displacement 1", "Displacement 2",
                           "Displacement 3"},
}

_ELMER_BC_NAMES = {"ROOT": "clamped root x = 0", "BOTTOM": "bonded to the glass z = 0",
                   "SYMX": "mirror plane x = d/2", "SYMY": "mirror plane y = W/2"}
_ELMER_BC_FIXED = {"ROOT": (1, 2, 3), "BOTTOM": (1, 2, 3), "SYMX": (1,), "SYMY": (2,)}


def _elmer_sif(kind: str, spec: ExportSpec, mesh: DeckMesh, mesh_dir: str, stem: str) -> str:
    sif = [f"! mapsim {kind} deck for ElmerSolver (SI units: m, Pa, kg/m^3, N/m^3)",
           f"! mesh: {mesh_dir}/ (ElmerGrid format, quadratic tetrahedra 510); probed point "
           f"{', '.join(_g(x) for x in mesh.tip_m)} m",
           "Header", "  CHECK KEYWORDS Warn", f'  Mesh DB "." "{mesh_dir}"',
           '  Results Directory ""', "End", "",
           "Simulation", "  Max Output Level = 5", '  Coordinate System = "Cartesian 3D"',
           '  Simulation Type = "Steady State"', "  Steady State Max Iterations = 1",
           "  Output Intervals = 1", "End", "",
           "Constants", "  ! not used by StressSolver: the self-weight is in the body force",
           "  Gravity(4) = 0 0 -1 9.81", "End", "",
           "Body 1", f'  Name = "{spec.name}"', "  Target Bodies(1) = 1", "  Equation = 1",
           f"  Material = {spec.index}", f"  Body Force = {spec.index}", "End", "",
           "Solver 1", '  Equation = "Linear elasticity"',
           '  Procedure = "StressSolve" "StressSolver"', "  Variable = -dofs 3 Displacement",
           "  Calculate Stresses = False",
           "  Linear System Solver = Direct", "  Linear System Direct Method = UMFPack",
           "  Steady State Convergence Tolerance = 1.0e-8", "End", "",
           "Solver 2", '  Exec Solver = "After Simulation"', '  Equation = "Result Output"',
           '  Procedure = "ResultOutputSolve" "ResultOutputSolver"',
           f'  Output File Name = "{stem}"', "  Vtu Format = True", "End", "",
           "Solver 3", '  Exec Solver = "After Simulation"', '  Equation = "Save Tip"',
           '  Procedure = "SaveData" "SaveScalars"', f'  Filename = "{stem}_tip.dat"',
           "  Save Coordinates(1,3) = " + " ".join(_g(x) for x in mesh.tip_m), "End", "",
           "Equation 1", '  Name = "elasticity"', "  Active Solvers(1) = 1", "End", ""]
    sif += to_elmer(spec).rstrip("\n").split("\n")
    sif.append("")
    for k, name in enumerate(mesh.boundaries, start=1):
        sif += [f"Boundary Condition {k}", f'  Name = "{_ELMER_BC_NAMES[name]}"',
                f"  Target Boundaries(1) = {k}"]
        sif += [f"  Displacement {c} = Real 0.0" for c in _ELMER_BC_FIXED[name]]
        sif += ["End", ""]
    return "\n".join(sif)


def _write_elmer_mesh(directory, mesh: DeckMesh) -> list:
    from pathlib import Path
    from micro.common.files import atomic_path
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    nb = sum(len(f) for f, _ in mesh.boundaries.values())
    files = {}
    types = [(510, len(mesh.elements))] + ([(306, nb)] if nb else [])
    files["mesh.header"] = "\n".join([f"{len(mesh.nodes_m)} {len(mesh.elements)} {nb}",
                                      f"{len(types)}"] + [f"{t} {n}" for t, n in types]) + "\n"
    files["mesh.nodes"] = "".join(f"{k + 1} -1 {_g(x)} {_g(y)} {_g(z)}\n"
                                  for k, (x, y, z) in enumerate(mesh.nodes_m))
    files["mesh.elements"] = "".join(f"{e + 1} 1 510 " + " ".join(str(i + 1) for i in conn) + "\n"
                                     for e, conn in enumerate(mesh.elements))
    lines, k = [], 0
    for tag, (faces, parents) in enumerate(mesh.boundaries.values(), start=1):
        for f, par in zip(faces, parents):
            k += 1
            lines.append(f"{k} {tag} {par + 1} 0 306 " + " ".join(str(i + 1) for i in f))
    files["mesh.boundary"] = "\n".join(lines) + ("\n" if lines else "")
    out = []
    for name, text in files.items():
        with atomic_path(d / name) as tmp:
            tmp.write_text(text)
        out.append(d / name)
    return out


def write_deck(kind: str, solver: str, spec: ExportSpec, geometry, out_path, *,
               element: str | None = None, divisions=None, nz: int | None = None,
               aspect: float | None = None, nc: int = 2, channel_aspect: float = 4.0,
               nlgeom: str = "off", body_force=None, notes=()) -> Deck:
    """Write a complete, runnable input deck for the cantilever or the channel.

    Parameters
    ----------
    kind : "cantilever" | "channel"
    solver : "abaqus" (one ``.inp``, also for CalculiX: ``ccx -i <stem>``) | "elmer"
        (``.sif`` plus the ElmerGrid-format mesh directory ``<stem>_mesh`` next to it)
    spec : ExportSpec -- material, body force [N/m^3] and direction, gravity [m/s^2]
    geometry : Strip (cantilever) or ChannelGeometry (channel) [m]
    out_path : path of the ``.inp`` or ``.sif``
    element, divisions, nz, aspect, nc, channel_aspect : the mesh (:func:`deck_mesh`); None:
        the cantilever's Abaqus default :data:`DECK_ELEMENT` (``C3D20R``) on
        ``beam_divisions(strip, DECK_NZ, DECK_ASPECT)``; the channel and Elmer decks are
        quadratic tetrahedra (``element="C3D10"``)
    nlgeom : "auto" | "on" | "off" -- ``*STEP, NLGEOM`` (Abaqus/CalculiX); "auto": when
        :func:`linear_deflection_estimate_m` exceeds :data:`NLGEOM_FRACTION` of the thickness
        (``mapsim export --nlgeom``'s default; this function's default "off" keeps the linear
        twins of :mod:`homogenize.macro.elements` linear). Elmer decks are linear
        (StressSolver): "on" is refused there
    body_force : None, or ``f(points_m (n, 3)) -> (n, 3)`` [N/m^3] (e.g.
        :func:`magnet_body_force`): a body force varying over the strip, evaluated at each
        element's centroid of the undeformed strip and written per element (``*DLOAD`` ``BX``,
        ``BY``, ``BZ``); ``spec.body_force_N_m3`` must then be 0 (its direction still orients
        gravity). Abaqus cantilever decks only
    notes : comment lines written at the top of an Abaqus deck (e.g. the magnet)

    Returns
    -------
    Deck with the files written (deck first), the mesh (its ``tip_node``, 0-based, is the
    node of set ``NTIP``), ``nlgeom`` and the estimate, and the per-element loads.
    """
    from pathlib import Path
    from micro.common.files import atomic_path
    check_choice("solver", solver, DECK_SOLVERS)
    check_choice("kind", kind, DECK_KINDS)
    check_choice("nlgeom", nlgeom, NLGEOM_MODES)
    if element is None:
        element = DECK_ELEMENT if (kind == "cantilever" and solver == "abaqus") else "C3D10"
    nz = DECK_NZ if nz is None else nz
    aspect = DECK_ASPECT if aspect is None else aspect
    if solver == "elmer" and nlgeom == "on":
        raise InputError("nlgeom 'on': the Elmer deck is linear elasticity (StressSolver); "
                         "use the abaqus deck (CalculiX) for a geometrically nonlinear step")
    if body_force is not None:
        if kind != "cantilever" or solver != "abaqus":
            raise InputError("a varying body force (a magnet) is written into the abaqus "
                             "cantilever deck only")
        if not callable(body_force):
            raise InputError("body_force must be a callable f(points_m) -> (n, 3) [N/m^3]")
        if spec.body_force_N_m3 != 0:
            raise InputError("give either a uniform body force or a magnet's varying force, "
                             "not both")
    if solver == "elmer" and element != "C3D10":
        raise InputError(f"element {element!r}: Elmer decks use quadratic tetrahedra "
                         f"(element='C3D10', Elmer type 510)")
    out = Path(out_path)
    mesh_path = out.parent / (out.stem + "_mesh")
    if solver == "elmer" and os.path.lexists(mesh_path) and not mesh_path.is_dir():
        raise InputError(f"{mesh_path} exists and is not a directory; the Elmer deck {out} "
                         f"writes its mesh there: move it away or give another --out")
    mesh = deck_mesh(kind, geometry, element=element, divisions=divisions, nz=nz,
                     aspect=aspect, nc=nc, channel_aspect=channel_aspect)
    loads = vols = None
    if body_force is not None:
        cen, vols = element_centroids_volumes(mesh)
        loads = np.asarray(body_force(cen), float)
        if loads.shape != cen.shape or not np.all(np.isfinite(loads)):
            raise InputError(f"body_force must return finite (n, 3) values [N/m^3], got shape "
                             f"{loads.shape}")
    estimate = linear_deflection_estimate_m(kind, spec, geometry, loads, mesh)
    thickness = geometry.c_m if kind == "channel" else geometry.thickness_m
    on = nlgeom == "on" or (nlgeom == "auto" and solver == "abaqus"
                            and estimate > NLGEOM_FRACTION * thickness)
    if solver == "abaqus":
        with atomic_path(out) as tmp:
            tmp.write_text(_abaqus_deck(kind, spec, mesh, nlgeom=on, estimate_m=estimate,
                                        element_loads=loads, notes=tuple(notes)))
        return Deck(kind, solver, (out,), mesh, spec, on, estimate, loads, vols)
    mesh_dir = out.stem + "_mesh"
    mesh_files = _write_elmer_mesh(out.parent / mesh_dir, mesh)
    with atomic_path(out) as tmp:
        tmp.write_text(_elmer_sif(kind, spec, mesh, mesh_dir, out.stem))
    return Deck(kind, solver, (out, *mesh_files), mesh, spec)


def parse_ccx_dat(text: str) -> dict:
    """Nodal displacements printed by CalculiX (``*NODE PRINT`` U) in a ``.dat`` file.

    Returns {node id (1-based): ndarray (3,) [m]} of the last block printed.
    """
    out: dict = {}
    block = None
    for line in text.splitlines():
        if "displacements" in line.lower():
            block = {}
            out = block
            continue
        parts = line.split()
        if block is not None and len(parts) == 4:
            try:
                block[int(parts[0])] = np.array([float(v) for v in parts[1:]])
            except ValueError:
                block = None
    if not out:
        raise InputError("no displacement block (*NODE PRINT U) in the CalculiX .dat text")
    return out


def parse_sif(text: str) -> dict:
    """Sections of an Elmer ``.sif``: {("Material", 1): {keyword: value text}, ...}.

    Comments (``!``) are dropped; keyword names are returned without their size suffix
    (``Gravity(4)`` -> ``Gravity``). Raises InputError on an unterminated section, on a
    keyword outside :data:`ELMER_KEYWORDS` or a section unknown there.
    """
    sections: dict = {}
    current = None
    for raw in text.splitlines():
        line = raw.split("!", 1)[0].strip()
        if not line:
            continue
        if current is None:
            m = re.fullmatch(r"([A-Za-z][A-Za-z ]*?)(?:\s+(\d+))?", line)
            if not m or m.group(1) not in ELMER_KEYWORDS:
                raise InputError(f"unknown .sif section {line!r}; known: "
                                 f"{', '.join(ELMER_KEYWORDS)}")
            current = (m.group(1), int(m.group(2)) if m.group(2) else None)
            sections[current] = {}
            continue
        if line == "End":
            current = None
            continue
        if "=" in line:
            key, value = (x.strip() for x in line.split("=", 1))
        else:
            # keyword and value(s) without "=" (e.g. Mesh DB "." "mesh"): the longest keyword
            # of the section that starts the line
            known = sorted((k for k in ELMER_KEYWORDS[current[0]]
                            if line.upper().startswith(k.upper() + " ")), key=len)
            key = known[-1] if known else line.split()[0]
            value = line[len(key):].strip()
        key = re.sub(r"\(.*\)$", "", key).strip()
        if key not in ELMER_KEYWORDS[current[0]]:
            raise InputError(f"keyword {key!r} is not among the documented keywords of the "
                             f"{current[0]} section: {sorted(ELMER_KEYWORDS[current[0]])}")
        sections[current][key] = value
    if current is not None:
        raise InputError(f"section {current} has no End")
    return sections


def read_elmer_mesh(directory) -> dict:
    """Read an ElmerGrid-format mesh back: {nodes_m (N, 3), elements (E, 10) 0-based,
    boundary_tags (F,), boundary_parents (F,) 0-based, boundary (F, 6) 0-based, header}.

    Checks the counts of ``mesh.header`` against the files and that every index is in range.
    """
    from pathlib import Path
    d = Path(directory)
    head = [ln.split() for ln in (d / "mesh.header").read_text().splitlines() if ln.strip()]
    nn, ne, nb = (int(v) for v in head[0])
    types = {int(t): int(n) for t, n in head[2:2 + int(head[1][0])]}
    nodes = np.loadtxt(d / "mesh.nodes", ndmin=2)
    elems = np.loadtxt(d / "mesh.elements", dtype=np.int64, ndmin=2)
    btext = (d / "mesh.boundary").read_text().strip()
    bnd = np.array([[int(v) for v in ln.split()] for ln in btext.splitlines()],
                   dtype=np.int64).reshape(-1, 11)
    if len(nodes) != nn or len(elems) != ne or len(bnd) != nb:
        raise InputError(f"{d}: mesh.header counts {nn, ne, nb} differ from the files "
                         f"{len(nodes), len(elems), len(bnd)}")
    if types.get(510, 0) != ne or (nb and types.get(306, 0) != nb):
        raise InputError(f"{d}: element types in mesh.header {types} do not match the files")
    if not np.array_equal(nodes[:, 0], np.arange(1, nn + 1)) or np.any(elems[:, 2] != 510):
        raise InputError(f"{d}: node ids not consecutive or element types not 510")
    conn = elems[:, 3:] - 1
    if conn.min() < 0 or conn.max() >= nn or (nb and (bnd[:, 5:].max() > nn
                                                     or bnd[:, 2].max() > ne)):
        raise InputError(f"{d}: index out of range")
    return {"nodes_m": nodes[:, 2:5], "elements": conn, "boundary_tags": bnd[:, 1],
            "boundary_parents": bnd[:, 2] - 1, "boundary": bnd[:, 5:] - 1, "header": head}
