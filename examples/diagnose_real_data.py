"""Diagnose the three real data sets shipped in examples/data (see PROVENANCE.md there).

Importing this module runs the diagnoses and exposes the results (the spec's JSON dicts):
``seed_point``, ``diguet``, ``rtv615``. Run it as a script to (re)write the reports under
results/diagnose/ with the discussions of results/diagnose/discussions/.
"""
from pathlib import Path

from homogenize.experiments import diagnose, load_experiment, write_report

HERE = Path(__file__).resolve().parent
DATA = HERE / "data"
NAMES = ("seed_paper_cantilever", "diguet2010_magnetostriction", "rtv615_tensile")

#: the magnetostriction data set is also predicted as measured (its change of length) by the
#: specimen solver, three models, nothing fitted (report section "The specimen predicted as
#: measured"); the other kinds have no specimen account
SPECIMEN_MESH = "normal"
diagnoses = {name: diagnose(load_experiment(DATA / f"{name}.toml"), specimen_mesh=SPECIMEN_MESH)
             for name in NAMES}
seed_point = diagnoses["seed_paper_cantilever"].as_dict()
diguet = diagnoses["diguet2010_magnetostriction"].as_dict()
rtv615 = diagnoses["rtv615_tensile"].as_dict()

if __name__ == "__main__":
    from micro.common.files import manifest, write_json
    out = HERE.parent / "results" / "diagnose"
    for name, d in diagnoses.items():
        disc = out / "discussions" / f"{name}.md"
        md = write_report(d, out / name, discussion=disc.read_text() if disc.exists() else None)
        write_json(out / name / "diagnosis.json", d.as_dict())
        write_json(out / name / "manifest.json",
                   manifest({"experiment": f"examples/data/{name}.toml", "command": "diagnose"}, None))
        print(f"{name}: causes {d.as_dict()['causes']}, gain {d.as_dict()['gain']:.3g} -> {md}")
