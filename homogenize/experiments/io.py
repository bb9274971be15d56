"""Measured experiments: one TOML file plus one CSV file (see ``examples/data/EXPERIMENT_FORMAT.md`` in the project).

:func:`load_experiment` reads and validates both files completely before returning; any
problem raises :class:`micro.common.validate.InputError` with ONE message naming the file, the row
(1-based line number in the file, the header being row 1) and the column. Nothing is converted
silently: units are SI as the spec says, and a value outside its physical range is refused.
"""
from __future__ import annotations

import csv
import math
import tomllib
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from micro.common.validate import InputError, check_regular_file
from micro.common.files import atomic_write_text
from micro.materials import GRAVITY_M_S2, PDMS, SEED

__all__ = ["KINDS", "REQUIRED", "OPTIONAL", "MEASURED", "Matrix", "Particles", "Setup",
           "Experiment", "load_experiment", "write_experiment"]

KINDS = ("deflection", "magnetization", "magnetostriction", "tensile")

REQUIRED = {
    "deflection": ("specimen", "phi", "length_m", "width_m", "thickness_m", "B_T",
                   "gradB_T_per_m", "deflection_m"),
    "magnetization": ("specimen", "phi", "H_A_per_m", "M_A_per_m"),
    "magnetostriction": ("specimen", "phi", "aspect_ratio", "B_T", "strain"),
    "tensile": ("specimen", "phi", "strain", "stress_Pa"),
}
OPTIONAL = {
    "deflection": ("deflection_sd_m", "radius_mean_m", "branch"),
    "magnetization": ("M_sd_A_per_m", "radius_mean_m", "aspect_ratio", "branch"),
    "magnetostriction": ("strain_sd", "radius_mean_m", "branch"),
    # branch is not in the spec's tensile row but 'absent means up' holds for every kind, and
    # loading/unloading branches are what reveal hysteresis of a tensile test.
    "tensile": ("stress_sd_Pa", "branch"),
}
MEASURED = {"deflection": "deflection_m", "magnetization": "M_A_per_m",
            "magnetostriction": "strain", "tensile": "stress_Pa"}
SD_COLUMN = {"deflection": "deflection_sd_m", "magnetization": "M_sd_A_per_m",
             "magnetostriction": "strain_sd", "tensile": "stress_sd_Pa"}

# Physical range of each numeric column: (lo, hi, lo_open, hi_open, unit, words).
_INF = math.inf
_RANGES = {
    "phi": (0.0, 0.74, True, True, "", "a particle volume fraction below random close packing"),
    "length_m": (0.0, _INF, True, True, "m", "a length"),
    "width_m": (0.0, _INF, True, True, "m", "a length"),
    "thickness_m": (0.0, _INF, True, True, "m", "a length"),
    "radius_mean_m": (0.0, _INF, True, True, "m", "a particle radius"),
    "aspect_ratio": (0.0, _INF, True, True, "", "length / diameter"),
    "B_T": (-_INF, _INF, True, True, "T", "a flux density"),
    "gradB_T_per_m": (-_INF, _INF, True, True, "T/m", "a field gradient"),
    "deflection_m": (-_INF, _INF, True, True, "m", "a deflection"),
    "H_A_per_m": (-_INF, _INF, True, True, "A/m", "a field"),
    "M_A_per_m": (-_INF, _INF, True, True, "A/m", "a magnetization"),
    "strain": (-1.0, _INF, True, True, "", "a strain (> -1: a length stays positive)"),
    "stress_Pa": (-_INF, _INF, True, True, "Pa", "a stress"),
    "deflection_sd_m": (0.0, _INF, True, True, "m", "a standard deviation"),
    "M_sd_A_per_m": (0.0, _INF, True, True, "A/m", "a standard deviation"),
    "strain_sd": (0.0, _INF, True, True, "", "a standard deviation"),
    "stress_sd_Pa": (0.0, _INF, True, True, "Pa", "a standard deviation"),
}
_STRING_COLUMNS = ("specimen", "branch")

#: largest experiment file (TOML or CSV) read [bytes]: far above any measured data set, far
#: below what would exhaust memory (a device such as /dev/zero never ends)
MAX_FILE_BYTES = 64 * 2 ** 20


@dataclass(frozen=True)
class Matrix:
    """Matrix polymer (defaults: the seed paper's PDMS)."""
    E_Pa: float = PDMS.E_Pa
    nu: float = PDMS.nu
    density_kg_m3: float = PDMS.density_kg_m3


@dataclass(frozen=True)
class Particles:
    """Magnetic filler (defaults: the seed paper's NANOFER 25 powder)."""
    density_kg_m3: float = SEED.particle_density_kg_m3
    sigma_s_Am2_kg: float = SEED.sigma_s_Am2_kg
    radius_mean_m: float = 25e-9
    radius_min_m: float = 10e-9
    radius_max_m: float = 50e-9

    @property
    def Ms_A_per_m(self) -> float:
        """Saturation magnetization of the particle material, rho * sigma_s [A/m]."""
        return self.density_kg_m3 * self.sigma_s_Am2_kg


@dataclass(frozen=True)
class Setup:
    """How the experiment was done."""
    gravity_m_s2: float = GRAVITY_M_S2
    deflection_reference: str = "field_off"
    gravity_along_force: bool = True


@dataclass(frozen=True, eq=False)
class Experiment:
    """A validated experiment: metadata plus the CSV columns as read-only float arrays.

    ``columns`` holds every numeric column the kind knows (required and present optional
    ones); ``specimen`` the specimen label of each row; ``down`` is True on falling branches.
    """
    kind: str
    toml_path: Path | None
    data_path: Path | None
    title: str
    matrix: Matrix
    particles: Particles
    setup: Setup
    columns: dict
    specimen: np.ndarray
    down: np.ndarray

    @property
    def n_rows(self) -> int:
        return int(self.specimen.size)

    @property
    def measured_name(self) -> str:
        return MEASURED[self.kind]

    @property
    def y(self) -> np.ndarray:
        """The measured column, in its SI unit."""
        return self.columns[MEASURED[self.kind]]

    @property
    def sd(self) -> np.ndarray | None:
        return self.columns.get(SD_COLUMN[self.kind])

    def has(self, name: str) -> bool:
        return name in self.columns

    @property
    def groups(self) -> np.ndarray:
        """Integer specimen code of each row (order of first appearance)."""
        _, first, inv = np.unique(self.specimen, return_index=True, return_inverse=True)
        rank = np.argsort(np.argsort(first))
        return rank[inv]

    def subset(self, idx) -> "Experiment":
        idx = np.asarray(idx)
        cols = {k: _ro(v[idx]) for k, v in self.columns.items()}
        return replace(self, columns=cols, specimen=_ro(self.specimen[idx]),
                       down=_ro(self.down[idx]))

    def with_measured(self, y) -> "Experiment":
        cols = dict(self.columns)
        cols[MEASURED[self.kind]] = _ro(np.asarray(y, dtype=float))
        return replace(self, columns=cols)


def _ro(a):
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


def _section(toml_file, doc, name, cls):
    raw = doc.get(name, {})
    if not isinstance(raw, dict):
        raise InputError(f"{toml_file}: [{name}] must be a table")
    known = {f.name: f for f in fields(cls)}
    values = {}
    for key, val in raw.items():
        if key not in known:
            raise InputError(f"{toml_file}: unknown key '{key}' in [{name}]; allowed: "
                             f"{', '.join(known)}")
        default = known[key].default
        if isinstance(default, bool):
            if not isinstance(val, bool):
                raise InputError(f"{toml_file}: [{name}] {key} must be true or false, got {val!r}")
        elif isinstance(default, str):
            if not isinstance(val, str):
                raise InputError(f"{toml_file}: [{name}] {key} must be a string, got {val!r}")
        else:
            if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
                raise InputError(f"{toml_file}: [{name}] {key} must be a finite number, got {val!r}")
            val = float(val)
        values[key] = val
    return cls(**values)


def _check_sections(toml_file, m: Matrix, p: Particles, s: Setup):
    def bad(where, msg):
        raise InputError(f"{toml_file}: {where} {msg}")
    if m.E_Pa <= 0:
        bad("[matrix] E_Pa", f"must be > 0 Pa, got {m.E_Pa:g}")
    if not -1.0 < m.nu < 0.5:
        bad("[matrix] nu", f"must be in (-1, 0.5), got {m.nu:g}")
    if m.density_kg_m3 <= 0:
        bad("[matrix] density_kg_m3", f"must be > 0 kg/m^3, got {m.density_kg_m3:g}")
    if p.density_kg_m3 <= 0:
        bad("[particles] density_kg_m3", f"must be > 0 kg/m^3, got {p.density_kg_m3:g}")
    if p.sigma_s_Am2_kg <= 0:
        bad("[particles] sigma_s_Am2_kg", f"must be > 0 A m^2/kg, got {p.sigma_s_Am2_kg:g}")
    for key in ("radius_mean_m", "radius_min_m", "radius_max_m"):
        if getattr(p, key) <= 0:
            bad(f"[particles] {key}", f"must be > 0 m, got {getattr(p, key):g}")
    if not p.radius_min_m <= p.radius_mean_m <= p.radius_max_m:
        bad("[particles]", f"needs radius_min_m <= radius_mean_m <= radius_max_m, got "
                           f"{p.radius_min_m:g} m, {p.radius_mean_m:g} m, {p.radius_max_m:g} m")
    if s.gravity_m_s2 < 0:
        bad("[setup] gravity_m_s2", f"must be >= 0 m/s^2, got {s.gravity_m_s2:g}")
    if s.deflection_reference not in ("field_off", "unloaded"):
        bad("[setup] deflection_reference",
            f"must be 'field_off' or 'unloaded', got {s.deflection_reference!r}")


def load_experiment(toml_path) -> Experiment:
    """Read and validate an experiment (TOML + CSV).

    Parameters
    ----------
    toml_path : str or Path -- the experiment's TOML file; its ``data`` key names the CSV,
        relative to the TOML file.

    Returns
    -------
    Experiment

    Raises
    ------
    InputError -- one message naming the file, row and column of the first problem.
    """
    toml_path = Path(toml_path)
    _check_regular(toml_path, "experiment file")
    try:
        text = toml_path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise InputError(f"{toml_path}: experiment file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{toml_path}: cannot read ({exc})") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{toml_path}: not valid TOML ({exc})") from None
    allowed = {"kind", "data", "title", "matrix", "particles", "setup"}
    for key in doc:
        if key not in allowed:
            raise InputError(f"{toml_path}: unknown key '{key}'; allowed: {', '.join(sorted(allowed))}")
    kind = doc.get("kind")
    if kind not in KINDS:
        raise InputError(f"{toml_path}: kind must be one of {', '.join(KINDS)}; got {kind!r}")
    data = doc.get("data")
    if not isinstance(data, str) or not data:
        raise InputError(f"{toml_path}: data must name the CSV file (relative to the TOML file)")
    title = doc.get("title", "")
    if not isinstance(title, str):
        raise InputError(f"{toml_path}: title must be a string, got {title!r}")
    matrix = _section(toml_path, doc, "matrix", Matrix)
    particles = _section(toml_path, doc, "particles", Particles)
    setup = _section(toml_path, doc, "setup", Setup)
    _check_sections(toml_path, matrix, particles, setup)
    csv_path = (toml_path.parent / data)
    cols, specimen, down, lines = _read_csv(csv_path, kind)
    _check_plausible(csv_path, kind, cols, specimen, down, lines, matrix, particles)
    return Experiment(kind=kind, toml_path=toml_path, data_path=csv_path, title=title,
                      matrix=matrix, particles=particles, setup=setup, columns=cols,
                      specimen=specimen, down=down)


def _check_regular(path: Path, what: str) -> None:
    """A file we read must be a regular file of bounded size (not a device, FIFO, directory)."""
    check_regular_file(path, f"{path}: {what}", MAX_FILE_BYTES, missing="not found",
                       unreadable="cannot read")


def _check_plausible(path, kind, cols, specimen, down, lines, matrix, particles) -> None:
    """Refuse data that contradict their declared units or kind, before any fit: a fit would
    otherwise land on a bound of its parameter without a word. One message naming file, row
    and column; the checks are loose enough for any real specimen."""
    def bad(i, col, msg):
        raise InputError(f"{path}, row {lines[i]}, column '{col}': {msg}")
    # exact duplicate rows (a copy-paste): every column and label equal
    seen = {}
    keys = sorted(cols)
    for i in range(len(lines)):
        row = (str(specimen[i]), bool(down[i])) + tuple(float(cols[k][i]) for k in keys)
        if row in seen:
            raise InputError(f"{path}, row {lines[i]}: repeats row {lines[seen[row]]} exactly "
                             f"(a duplicated row?); remove it or label repeats as their own "
                             f"specimen")
        seen[row] = i
    if "B_T" in cols:
        i = int(np.argmax(np.abs(cols["B_T"])))
        if abs(cols["B_T"][i]) > 50.0:
            bad(i, "B_T", f"{cols['B_T'][i]:g} T is beyond any laboratory magnet (50 T); "
                          f"a value in mT?")
    if kind == "tensile":
        eps, sig = cols["strain"], cols["stress_Pa"]
        i = int(np.argmax(eps))
        if eps[i] > 10.0:
            bad(i, "strain", f"{eps[i]:g} is a 1000 % strain; strain is a fraction (0.1 = 10 %), "
                             f"not percent")
        big = float(np.max(np.abs(sig))) if sig.size else 0.0
        for i in np.flatnonzero((eps > 0) & (sig < -0.01 * big)):
            bad(int(i), "stress_Pa", f"{sig[i]:g} Pa is compressive at a tensile strain "
                                     f"{eps[i]:g}; tensile stress is positive")
        sel = eps > 1e-3
        if np.any(sel):
            modulus = float(np.median(sig[sel] / eps[sel]))
            ratio = modulus / matrix.E_Pa
            if not 1e-3 <= ratio <= 1e3:
                i = int(np.flatnonzero(sel)[0])
                hint = "stress in MPa or kPa?" if ratio < 1 else "strain in percent?"
                bad(i, "stress_Pa", f"the data imply a modulus of {modulus:.3g} Pa, "
                                    f"{ratio:.1e} times [matrix] E_Pa = {matrix.E_Pa:g} Pa; "
                                    f"{hint} (columns are SI: Pa and a strain fraction)")
    elif kind == "magnetostriction":
        i = int(np.argmax(np.abs(cols["strain"])))
        if abs(cols["strain"][i]) > 0.5:
            bad(i, "strain", f"{cols['strain'][i]:g} is a {100 * cols['strain'][i]:g} % "
                             f"magnetostrictive strain; strain is a fraction, not percent")
    elif kind == "deflection":
        ratio = np.abs(cols["deflection_m"]) / cols["length_m"]
        i = int(np.argmax(ratio))
        if ratio[i] > 1.0:
            bad(i, "deflection_m", f"{cols['deflection_m'][i]:g} m exceeds the strip length "
                                   f"{cols['length_m'][i]:g} m; a value in mm?")
    elif kind == "magnetization":
        M, phi = cols["M_A_per_m"], cols["phi"]
        limit = 1.5 * phi * particles.Ms_A_per_m + 1.0
        i = int(np.argmax(np.abs(M) / limit))
        if abs(M[i]) > limit[i]:
            bad(i, "M_A_per_m", f"{M[i]:g} A/m exceeds the saturation of the filler, phi Ms = "
                                f"{phi[i] * particles.Ms_A_per_m:.4g} A/m; a value in emu/g or "
                                f"kA/m? (the column is the composite's M in A/m)")


def _read_csv(path: Path, kind: str):
    _check_regular(path, "data file")
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except FileNotFoundError:
        raise InputError(f"{path}: data file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read ({exc})") from None
    rows = list(csv.reader(text.splitlines()))
    # keep the file's line numbers: the header is row 1
    numbered = [(i + 1, r) for i, r in enumerate(rows) if r and any(c.strip() for c in r)]
    if not numbered:
        raise InputError(f"{path}: empty file; a header row is required")
    head_row, header = numbered[0]
    header = [h.strip() for h in header]
    seen = set()
    for h in header:
        if h in seen:
            raise InputError(f"{path}, row {head_row}, column '{h}': duplicate column name")
        seen.add(h)
    # a second column for a quantity the file already gives (stress_MPa beside stress_Pa,
    # deflection_mm beside deflection_m): which one is meant is not said
    known = [c for c in REQUIRED[kind] + OPTIONAL[kind] if c in seen]
    for h in header:
        if h in known:
            continue
        base = h.split("_")[0].lower()
        twin = [c for c in known if c.split("_")[0].lower() == base]
        if base and twin:
            raise InputError(f"{path}, row {head_row}, column '{h}': a second column for "
                             f"'{twin[0]}' (another unit?); which one to use is ambiguous: keep "
                             f"only '{twin[0]}' (SI units)")
    for name in REQUIRED[kind]:
        if name not in seen:
            raise InputError(f"{path}, row {head_row}, column '{name}': required column missing "
                             f"for kind '{kind}' (header has: {', '.join(header)})")
    body = numbered[1:]
    if not body:
        raise InputError(f"{path}: no data rows after the header")
    wanted = [c for c in REQUIRED[kind] + OPTIONAL[kind] if c in seen]
    index = {h: i for i, h in enumerate(header)}
    values = {c: [] for c in wanted}
    for line, r in body:
        if len(r) != len(header):
            raise InputError(f"{path}, row {line}: {len(r)} fields but the header has {len(header)}")
        for c in wanted:
            cell = r[index[c]].strip()
            if c in _STRING_COLUMNS:
                if c == "specimen" and not cell:
                    raise InputError(f"{path}, row {line}, column 'specimen': empty label")
                if c == "branch" and cell not in ("up", "down"):
                    raise InputError(f"{path}, row {line}, column 'branch': must be 'up' or "
                                     f"'down', got {cell!r}")
                values[c].append(cell)
                continue
            try:
                v = float(cell)
            except ValueError:
                raise InputError(f"{path}, row {line}, column '{c}': not a number: {cell!r}") from None
            if not math.isfinite(v):
                raise InputError(f"{path}, row {line}, column '{c}': must be finite, got {cell!r}")
            lo, hi, lo_open, hi_open, unit, words = _RANGES[c]
            if c == "phi" and kind == "tensile":
                lo_open = False      # an unfilled matrix (phi = 0) is a legitimate tensile test
            if (v < lo or (lo_open and v == lo)) or (v > hi or (hi_open and v == hi)):
                left = "(" if lo_open else "["
                right = ")" if hi_open else "]"
                u = f" {unit}" if unit else ""
                raise InputError(f"{path}, row {line}, column '{c}': {v:g}{u} is not {words}; "
                                 f"allowed {left}{lo:g}, {hi:g}{right}{u}")
            values[c].append(v)
    cols = {c: _ro(np.asarray(v, dtype=float)) for c, v in values.items()
            if c not in _STRING_COLUMNS}
    specimen = _ro(np.asarray(values["specimen"], dtype=str))
    down = _ro(np.asarray([b == "down" for b in values.get("branch", ["up"] * len(body))]))
    return cols, specimen, down, [line for line, _ in body]


def write_experiment(toml_path, exp_or_kind, columns: dict, *, title: str = "",
                     matrix: Matrix | None = None, particles: Particles | None = None,
                     setup: Setup | None = None) -> None:
    """Write an experiment as TOML + CSV (atomically; the CSV beside the TOML, same stem).

    ``columns`` maps column names to sequences of equal length (``specimen`` and ``branch``
    as strings). Floats are written with 17 significant digits so a reload is exact.
    """

    kind = exp_or_kind
    toml_path = Path(toml_path)
    csv_name = toml_path.with_suffix(".csv").name
    names = list(columns)
    n = len(next(iter(columns.values())))
    lines = [",".join(names)]
    for i in range(n):
        cells = []
        for c in names:
            v = columns[c][i]
            cells.append(str(v) if c in _STRING_COLUMNS else repr(float(v)))
        lines.append(",".join(cells))
    toml = [f'kind = "{kind}"', f'data = "{csv_name}"']
    if title:
        toml.append(f'title = "{title}"')
    for name, obj in (("matrix", matrix), ("particles", particles), ("setup", setup)):
        if obj is None:
            continue
        toml.append(f"\n[{name}]")
        for f in fields(obj):
            v = getattr(obj, f.name)
            if isinstance(v, bool):
                toml.append(f"{f.name} = {'true' if v else 'false'}")
            elif isinstance(v, str):
                toml.append(f'{f.name} = "{v}"')
            else:
                toml.append(f"{f.name} = {float(v)!r}")
    atomic_write_text(toml_path.with_suffix(".csv"), "\n".join(lines) + "\n")
    atomic_write_text(toml_path, "\n".join(toml) + "\n")
