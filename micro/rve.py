"""The representative volume element (RVE): spheres in a periodic cube, and its HDF5 I/O.

An :class:`RVE` is immutable: its arrays are private read-only copies. Positions are wrapped
into ``[0, L)^3``; every geometric question that involves periodic images is answered by its
box, :attr:`RVE.box` (a :class:`micro.box.PeriodicBox`: wrapping, minimum image, pair search).

HDF5 layout (``RVE.save``): one dataset per array field, each with a ``units`` attribute;
root attributes ``box_m`` (with ``box_m_units``), ``seed`` (``-1`` stored with
``seed_is_none=True`` for ``None``), ``params_json`` (the generator parameters as JSON),
``format`` = ``"mapsim-rve"`` and ``format_version``.
"""
from __future__ import annotations

import json
import os
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from micro.common.files import _default as _json_default, atomic_path, is_regular_file, open_regular, write_json
from micro.common.validate import InputError
from micro.materials import SEED
from micro.common.files import open_hdf5
import h5py

from micro.box import PeriodicBox

__all__ = ["RVE", "PeriodicBox", "FORMAT_VERSION", "check_sidecar_manifest", "sidecar_path"]

FORMAT_VERSION = 1

# (field name, unit, dtype) of the per-particle arrays, in file order.
_ARRAYS = (
    ("centers_m", "m", np.float64),
    ("radii_m", "m", np.float64),
    ("core_radii_m", "m", np.float64),
    ("m_sat_Am2", "A m^2", np.float64),
    ("mass_kg", "kg", np.float64),
    ("cluster_id", "1", np.int64),
)


def _frozen_array(name, value, dtype, shape):
    try:
        arr = np.array(value, dtype=dtype, copy=True, order="C")
    except (TypeError, ValueError):
        raise InputError(f"RVE.{name} must be a numeric array, "
                         f"got {type(value).__name__}") from None
    if arr.shape != shape:
        raise InputError(f"RVE.{name} must have shape {shape}, got {arr.shape}")
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        raise InputError(f"RVE.{name} must be finite")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class RVE:
    """Spherical (core-shell) particles in a periodic cube.

    Parameters
    ----------
    box_m : float
        Periodic cube edge L [m]; particle centres lie in ``[0, L)^3``.
    centers_m : ndarray, shape (N, 3)
        Particle centres [m].
    radii_m : ndarray, shape (N,)
        Outer particle radius (core + shell) [m].
    core_radii_m : ndarray, shape (N,)
        Fe core radius [m]; equal to ``radii_m`` when there is no shell.
    m_sat_Am2 : ndarray, shape (N,)
        Saturation moment of each particle [A m^2].
    mass_kg : ndarray, shape (N,)
        Mass of each particle [kg].
    cluster_id : ndarray of int64, shape (N,)
        ``-1`` for isolated particles, else the index of the cluster or chain.
    seed : int or None
        Seed the RVE was generated with.
    params : dict
        Generator parameters (JSON-serialisable).
    """

    box_m: float
    centers_m: np.ndarray
    radii_m: np.ndarray
    core_radii_m: np.ndarray
    m_sat_Am2: np.ndarray
    mass_kg: np.ndarray
    cluster_id: np.ndarray
    seed: int | None
    params: dict = field(compare=False)

    def __post_init__(self):
        try:
            box = float(self.box_m)
        except (TypeError, ValueError):
            raise InputError(f"RVE.box_m must be a number [m], got {self.box_m!r}") from None
        if not (math.isfinite(box) and box > 0):
            raise InputError(f"RVE.box_m must be > 0 m and finite, got {box:g}")
        object.__setattr__(self, "box_m", box)
        c = np.asarray(self.centers_m)
        if c.ndim != 2 or c.shape[1] != 3:
            raise InputError(f"RVE.centers_m must have shape (N, 3), got {c.shape}")
        n = c.shape[0]
        for name, _unit, dtype in _ARRAYS:
            shape = (n, 3) if name == "centers_m" else (n,)
            object.__setattr__(self, name, _frozen_array(name, getattr(self, name), dtype, shape))
        if np.any(self.radii_m <= 0):
            raise InputError("RVE.radii_m must be > 0 m")
        if np.any(self.core_radii_m < 0) or np.any(self.core_radii_m > self.radii_m * (1 + 1e-12)):
            raise InputError("RVE.core_radii_m must lie in [0, radii_m] m")
        if np.any(self.mass_kg < 0):
            raise InputError("RVE.mass_kg must be >= 0 kg")
        if np.any(self.m_sat_Am2 < 0):
            raise InputError("RVE.m_sat_Am2 must be >= 0 A m^2 (a saturation moment)")
        # Positions on the far face are the same points as on the near face: wrap them.
        wrapped = PeriodicBox(box).wrap(self.centers_m)
        if not np.array_equal(wrapped, self.centers_m):
            wrapped.setflags(write=False)
            object.__setattr__(self, "centers_m", wrapped)
        if self.seed is not None:
            object.__setattr__(self, "seed", int(self.seed))
        params = {} if self.params is None else self.params
        try:
            params = json.loads(json.dumps(params))
        except (TypeError, ValueError) as exc:
            raise InputError(f"RVE.params must be JSON-serialisable: {exc}") from None
        object.__setattr__(self, "params", params)

    def __eq__(self, other):
        """Equal when every field is identical (arrays compared exactly)."""
        if not isinstance(other, RVE):
            return NotImplemented
        return (self.box_m == other.box_m and self.seed == other.seed
                and self.params == other.params
                and all(np.array_equal(getattr(self, k), getattr(other, k))
                        for k, _u, _d in _ARRAYS))

    __hash__ = None

    # ------------------------------------------------------------------ derived quantities
    @property
    def n(self) -> int:
        """Number of particles."""
        return int(self.radii_m.shape[0])

    @property
    def volume_m3(self) -> float:
        """Box volume L^3 [m^3]."""
        return self.box_m ** 3

    @property
    def particle_volumes_m3(self) -> np.ndarray:
        """Outer volume of each particle, shape (N,) [m^3]."""
        return 4.0 / 3.0 * np.pi * self.radii_m ** 3

    @property
    def core_volumes_m3(self) -> np.ndarray:
        """Core volume of each particle, shape (N,) [m^3]."""
        return 4.0 / 3.0 * np.pi * self.core_radii_m ** 3

    @property
    def phi(self) -> float:
        """Particle volume fraction (outer volumes / box volume) [1]."""
        return float(self.particle_volumes_m3.sum() / self.volume_m3)

    @property
    def number_density_m3(self) -> float:
        """Particles per unit volume [1/m^3]."""
        return self.n / self.volume_m3

    @property
    def specific_moment_Am2_kg(self) -> float:
        """Mass-averaged specific saturation moment sum(m_sat) / sum(mass) [A m^2/kg]."""
        return float(self.m_sat_Am2.sum() / self.mass_kg.sum()) if self.n else float("nan")

    # ------------------------------------------------------------------ periodic geometry
    @property
    def box(self) -> PeriodicBox:
        """The periodic cube of edge ``box_m`` [m] (wrapping, minimum image, pair search)."""
        return PeriodicBox(self.box_m)

    def minimum_image(self, d_m: np.ndarray) -> np.ndarray:
        """Map separation vectors (..., 3) [m] to their shortest periodic image."""
        return self.box.minimum_image(d_m)

    def translated(self, shift_m) -> "RVE":
        """A copy with every centre moved by ``shift_m`` (3,) [m] and wrapped into the box."""
        shift = np.asarray(shift_m, dtype=float).reshape(3)
        return self._replace(centers_m=self.box.wrap(self.centers_m + shift))

    def _replace(self, **changes) -> "RVE":
        kw = {k: getattr(self, k) for k in ("box_m", "centers_m", "radii_m", "core_radii_m",
                                            "m_sat_Am2", "mass_kg", "cluster_id", "seed", "params")}
        kw.update(changes)
        return RVE(**kw)

    @classmethod
    def from_spheres(cls, box_m, centers_m, radii_m, *,
                     density_kg_m3=SEED.particle_density_kg_m3,
                     sigma_Am2_kg=SEED.sigma_s_Am2_kg, cluster_id=None, seed=None,
                     params=None) -> "RVE":
        """An RVE of homogeneous spheres (no shell), e.g. for tests and hand-built cases.

        ``density_kg_m3`` and ``sigma_Am2_kg`` (specific saturation moment) default to the
        seed paper's values (7870 kg/m^3, 178 A m^2/kg).
        """
        r = np.asarray(radii_m, dtype=float)
        mass = density_kg_m3 * 4.0 / 3.0 * np.pi * r ** 3
        cid = np.full(r.shape, -1, dtype=np.int64) if cluster_id is None else cluster_id
        return cls(box_m=box_m, centers_m=centers_m, radii_m=r, core_radii_m=r,
                   m_sat_Am2=sigma_Am2_kg * mass, mass_kg=mass, cluster_id=cid, seed=seed,
                   params=params or {})

    # ------------------------------------------------------------------ HDF5 I/O
    def save(self, path, manifest: dict | None = None) -> Path:
        """Write the RVE to HDF5 at ``path`` atomically (units as attributes); return the path.

        ``manifest`` (the run manifest) is stored inside the file as ``manifest_json``: it is
        the authoritative copy, a side-car ``<stem>.manifest.json`` is checked against it by
        :func:`check_sidecar_manifest`.
        """

        path = Path(path)
        with atomic_path(path) as tmp:
            with h5py.File(tmp, "w") as f:
                f.attrs["format"] = "mapsim-rve"
                f.attrs["format_version"] = FORMAT_VERSION
                f.attrs["box_m"] = self.box_m
                f.attrs["box_m_units"] = "m"
                f.attrs["seed"] = -1 if self.seed is None else int(self.seed)
                f.attrs["seed_is_none"] = self.seed is None
                f.attrs["params_json"] = json.dumps(self.params, sort_keys=True)
                f.attrs["n"] = self.n
                f.attrs["phi"] = self.phi
                if manifest is not None:
                    f.attrs["manifest_json"] = json.dumps(manifest, sort_keys=True,
                                                          default=_json_default)
                for name, unit, _dtype in _ARRAYS:
                    ds = f.create_dataset(name, data=getattr(self, name))
                    ds.attrs["units"] = unit
        return path

    @classmethod
    def load(cls, path) -> "RVE":
        """Read an RVE written by :meth:`save`; a missing or malformed file raises InputError.

        Besides its layout, the file's invariants are checked: a known ``format_version``, an
        ``n`` attribute equal to the number of particles, valid ``params_json``, no two
        particles overlapping (beyond round-off).
        """

        path = Path(path)
        with open_hdf5(path, "RVE file") as f:
            if _text(f.attrs.get("format")) != "mapsim-rve":
                raise InputError(f"RVE file {path} is not a mapsim RVE "
                                 f"(attribute 'format' missing)")
            try:
                version = int(f.attrs.get("format_version", -1))
            except (TypeError, ValueError):
                version = -1
            if version != FORMAT_VERSION:
                raise InputError(f"RVE file {path}: format_version "
                                 f"{f.attrs.get('format_version')!r} is not one this mapsim "
                                 f"reads ({FORMAT_VERSION})")
            kw = {}
            for name, unit, _dtype in _ARRAYS:
                if name not in f or not isinstance(f[name], h5py.Dataset):
                    raise InputError(f"RVE file {path}: dataset '{name}' missing")
                got = _text(f[name].attrs.get("units"))
                if got != unit:
                    raise InputError(f"RVE file {path}: dataset '{name}' has units {got!r}, "
                                     f"expected {unit!r}")
                kw[name] = f[name][()]
            try:
                seed = None if bool(f.attrs.get("seed_is_none", False)) \
                    else int(f.attrs["seed"])
                box = float(f.attrs["box_m"])
            except KeyError as exc:
                raise InputError(f"RVE file {path}: attribute {exc.args[0]!r} missing") from None
            except (TypeError, ValueError) as exc:
                raise InputError(f"RVE file {path}: attribute seed or box_m is not a number "
                                 f"({exc})") from None
            try:
                params = json.loads(_text(f.attrs.get("params_json", "{}")))
            except (TypeError, ValueError) as exc:
                raise InputError(f"RVE file {path}: attribute params_json is not valid JSON "
                                 f"({exc})") from None
            if not isinstance(params, dict):
                raise InputError(f"RVE file {path}: attribute params_json must hold a JSON "
                                 f"object, got {type(params).__name__}")
            n_attr = f.attrs.get("n")
            phi_attr = f.attrs.get("phi")
        try:
            rve = cls(box_m=box, seed=seed, params=params, **kw)
        except InputError as exc:
            raise InputError(f"RVE file {path}: {exc}") from None
        if n_attr is not None and int(n_attr) != rve.n:
            raise InputError(f"RVE file {path}: attribute n = {int(n_attr)} disagrees with the "
                             f"{rve.n} particles in its arrays")
        if phi_attr is not None and not math.isclose(float(phi_attr), rve.phi, rel_tol=1e-6):
            raise InputError(f"RVE file {path}: attribute phi = {float(phi_attr):g} disagrees "
                             f"with the volume fraction {rve.phi:.6g} of its particles and box "
                             f"(the file was edited or damaged)")
        pair = _first_overlap(rve)
        if pair is not None:
            i, j, depth = pair
            raise InputError(f"RVE file {path}: particles {i} and {j} overlap by {depth:.3g} m "
                             f"(centre distance below the sum of their radii); the file is "
                             f"damaged or not made by mapsim")
        return rve


def sidecar_path(path) -> Path:
    """The side-car manifest of an RVE file: ``<stem>.manifest.json`` beside it."""
    path = Path(path)
    return path.with_name(path.stem + ".manifest.json")


def check_sidecar_manifest(path) -> str | None:
    """Reconcile the side-car manifest of the RVE file ``path`` with the file.

    The file and its side-car are two writes; a kill between them leaves a side-car of an
    earlier run. If the file holds its manifest (``manifest_json``), a side-car that differs
    is rewritten from it; otherwise a side-car whose seed differs from the file's is flagged.
    Returns a note for the user, or None when there is nothing to say.
    """
    side = sidecar_path(path)
    if os.path.lexists(side) and not is_regular_file(side):
        return f"{side} is not a regular file (a FIFO or device?); left as it is"
    try:
        with open_regular(side, "r", encoding="utf-8") as fh:
            have = json.loads(fh.read())
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        have = None
    with open_hdf5(path, "RVE file") as f:
        inner = _text(f.attrs.get("manifest_json"))
        seed = None if bool(f.attrs.get("seed_is_none", False)) else f.attrs.get("seed")
    if inner is not None:
        try:
            want = json.loads(inner)
        except ValueError:
            return f"{path}: its stored manifest is not valid JSON; {side} left as it is"
        if have == want:
            return None
        try:
            write_json(side, want)
        except OSError as exc:
            return f"{side} disagrees with the manifest inside {path} and cannot be " \
                   f"rewritten ({exc.strerror})"
        return f"{side} disagreed with the manifest inside {path} (authoritative): rewritten"
    side_seed = have.get("seed") if isinstance(have, dict) else None
    file_seed = None if seed is None else int(seed)
    if have is None or side_seed != file_seed:
        return f"{side} does not describe {path} (seed {side_seed} vs {file_seed}); the file " \
               f"is authoritative"
    return None


def _text(v):
    return v.decode() if isinstance(v, bytes) else v


#: relative overlap tolerated as round-off: placement leaves touching particles at exactly
#: r_i + r_j, reached to ~1e-15 relative after the wrap into the box
_OVERLAP_RTOL = 1e-9


def _first_overlap(rve: "RVE"):
    """(i, j, depth [m]) of the deepest overlapping pair of particles (periodic), or None."""
    if rve.n < 2:
        return None
    r = rve.radii_m
    i, j, dist = rve.box.pairs_within(rve.centers_m, 2.0 * float(r.max()))
    depth = (r[i] + r[j]) * (1 - _OVERLAP_RTOL) - dist
    k = int(np.argmax(depth)) if len(depth) else 0
    if len(depth) and depth[k] > 0:
        return int(i[k]), int(j[k]), float(depth[k] / (1 - _OVERLAP_RTOL))
    return None
