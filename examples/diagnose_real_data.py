"""Diagnose the three real data sets shipped in examples/data (see PROVENANCE.md there).

``diagnose_all()`` runs the diagnoses: ``{name: Diagnosis}`` (``.as_dict()`` is the spec's
JSON dict). Run this file as a script to (re)write the reports under results/diagnose/ with the
discussions of results/diagnose/discussions/.
"""
from pathlib import Path

from homogenize.experiments import diagnose, load_experiment, write_report

HERE = Path(__file__).resolve().parent
DATA = HERE / "data"
NAMES = ("seed_paper_cantilever", "diguet2010_magnetostriction", "rtv615_tensile")

#: the magnetostriction data set is also predicted as measured (its change of length) by the
#: specimen solver, three models, nothing fitted (report section "The specimen predicted as
#: measured"); the other kinds have no specimen account. "normal" is the mesh of the committed
#: reports; "coarse" (a quarter of the elements) is the quick check the test suite runs
SPECIMEN_MESH = "normal"


def diagnose_all(specimen_mesh: str = SPECIMEN_MESH) -> dict:
    """``{name: Diagnosis}`` of the data sets :data:`NAMES`."""
    return {name: diagnose(load_experiment(DATA / f"{name}.toml"), specimen_mesh=specimen_mesh)
            for name in NAMES}


if __name__ == "__main__":
    from micro.common.files import manifest, write_json
    out = HERE.parent / "results" / "diagnose"
    for name, d in diagnose_all().items():
        disc = out / "discussions" / f"{name}.md"
        md = write_report(d, out / name, discussion=disc.read_text() if disc.exists() else None)
        write_json(out / name / "diagnosis.json", d.as_dict())
        write_json(out / name / "manifest.json",
                   manifest({"experiment": f"examples/data/{name}.toml", "command": "diagnose"}, None))
        print(f"{name}: causes {d.as_dict()['causes']}, gain {d.as_dict()['gain']:.3g} -> {md}")
