"""The ``mapsim rve`` command (homogenize/_cli_rve.py)."""
import json

import pytest

from homogenize.cli import main
from micro import RVE


def test_rve_command_writes_everything(tmp_path, capsys):
    out = tmp_path / "rve.h5"
    rc = main(["rve", "--phi", "0.02", "--n", "300", "--seed", "1", "--out", str(out),
               "--json", str(tmp_path / "s.json"), "--ply", str(tmp_path / "p.ply"),
               "--glb", str(tmp_path / "p.glb"), "--png", str(tmp_path / "p.png"),
               "--arrangement", "clusters", "--cluster-size", "6", "--agglomerated-fraction",
               "0.5", "--gap", "1e-9"])
    assert rc == 0
    text = capsys.readouterr().out
    for words in ("particles            300", "box edge", "volume fraction      0.02",
                  "radius [nm]", "clusters"):
        assert words in text
    rve = RVE.load(out)
    summary = json.loads((tmp_path / "s.json").read_text())["summary"]
    assert summary["n"] == rve.n == 300
    assert summary["box_m"] == pytest.approx(rve.box_m, rel=1e-15)
    assert summary["phi"] == pytest.approx(0.02, rel=1e-12)
    assert summary["clusters"]["n_clusters"] == 25
    assert summary["min_gap_m"] >= 1e-9 * (1 - 1e-9)
    man = json.loads((tmp_path / "rve.manifest.json").read_text())
    assert man["seed"] == 1 and man["config"]["cluster_size"] == 6
    for f in ("p.ply", "p.glb", "p.png"):
        assert (tmp_path / f).stat().st_size > 1000
    # Same command line, same RVE.
    assert main(["rve", "--phi", "0.02", "--n", "300", "--seed", "1", "--out",
                 str(tmp_path / "again.h5"), "--arrangement", "clusters", "--cluster-size", "6",
                 "--agglomerated-fraction", "0.5", "--gap", "1e-9"]) == 0
    assert RVE.load(tmp_path / "again.h5") == rve


def test_core_shell_and_histogram_options(tmp_path, capsys):
    h = tmp_path / "h.csv"
    h.write_text("radius_m,count\n15e-9,3\n25e-9,5\n35e-9,2\n")
    assert main(["rve", "--n", "200", "--histogram", str(h), "--shell", "3e-9",
                 "--calibrate-sigma", "150", "--json", str(tmp_path / "s.json")]) == 0
    s = json.loads((tmp_path / "s.json").read_text())["summary"]
    assert s["radius_m"]["min"] >= 10e-9 and s["radius_m"]["max"] <= 40e-9
    assert s["core_radius_mean_m"] == pytest.approx(s["radius_m"]["mean"] - 3e-9, rel=1e-12)
    assert abs(s["specific_moment_Am2_kg"] - 150) < 5      # calibrated on the population


@pytest.mark.parametrize("argv, words", [
    (["--phi", "0"], ["phi"]),
    (["--phi", "0.9"], ["phi", "0.6"]),
    (["--r-min", "6e-8"], ["r_min", "r_max"]),
    (["--shell=-1e-9"], ["--shell", "[0, 0.001] m"]),      # option range, at parse time
    (["--shell", "2e-8"], ["shell thickness", "smallest particle radius"]),
    (["--histogram", "nope.csv"], ["nope.csv", "does not exist"]),
    (["--out", "x.txt"], ["--out", ".h5"]),
    (["--chain-direction", "0", "0", "0", "--arrangement", "chains"], ["chain_direction"]),
])
def test_bad_input_exit_2_one_line_no_files(tmp_path, capsys, monkeypatch, argv, words):
    monkeypatch.chdir(tmp_path)
    try:        # option ranges are argparse types (SystemExit 2), the rest InputError (return 2)
        rc = main(["rve", "--n", "100", "--out", "r.h5", "--json", "s.json"] + argv
                  if "--out" not in argv else ["rve", "--n", "100"] + argv)
    except SystemExit as exc:
        rc = exc.code
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mapsim rve: error:") and "\n" not in err
    for w in words:
        assert w in err
    assert list(tmp_path.iterdir()) == [] or all(p.name == "nope.csv" for p in tmp_path.iterdir())


def test_argparse_errors_exit_2(capsys):
    # main() returns argparse's usage-error code instead of raising SystemExit
    assert main(["rve", "--arrangement", "rods"]) == 2
    assert main(["rve", "--n", "ten"]) == 2


def test_help_states_units_and_defaults(capsys):
    assert main(["rve", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for opt in ("--phi", "--mean-radius", "--shell", "--gap", "--cluster-density"):
        assert opt in text
    assert "[m]" in text and "[kg/m^3]" in text and "[A m^2/kg]" in text
    assert "(default: 2.5e-08)" in text


def test_load_summarises_existing_file(tmp_path, capsys):
    from micro import RVE as _RVE
    r = _RVE.from_spheres(1e-6, [[0, 0, 0], [5e-7, 5e-7, 5e-7]], [1e-8, 2e-8], seed=5)
    r.save(tmp_path / "hand.h5")
    assert main(["rve", "--load", str(tmp_path / "hand.h5"), "--json",
                 str(tmp_path / "s.json"), "--png", str(tmp_path / "p.png")]) == 0
    s = json.loads((tmp_path / "s.json").read_text())["summary"]
    assert s["n"] == 2 and s["seed"] == 5
    assert s["phi"] == pytest.approx(4 / 3 * 3.141592653589793 * 9e-24 / 1e-18, rel=1e-12)
    assert main(["rve", "--load", str(tmp_path / "missing.h5")]) == 2
    assert "does not exist" in capsys.readouterr().err


# --------------------------------------------------------------------------- issue 36
@pytest.mark.parametrize("word", ["-1e-6", "-1E-6", "-.5", "-2.5e+3", "-1", "-1.", "-inf",
                                  "-1_000"])
def test_negative_numbers_in_any_notation_reach_the_range_check(word, capsys):
    # argparse's own pattern reads "-1e-6" as an option ("expected one argument")
    assert main(["rve", "--mean-radius", word]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mapsim rve: error: --mean-radius must be") and "\n" not in err
    assert "expected one argument" not in err


def test_negative_number_pattern_and_parser_class():
    from homogenize.cli import build_parser
    from homogenize.cli._common import NEGATIVE_NUMBER, Parser
    for w in ("-1e-6", "-15.5e-3", "-0.5", "-.5", "-3", "-INF", "-nan", "-1e+06"):
        assert NEGATIVE_NUMBER.match(w), w
        float(w.replace("_", ""))
    for w in ("--n", "-h", "-e5", "-", "-1e", "-1e-", "--1", "-x1"):
        assert not NEGATIVE_NUMBER.match(w), w
    parser = build_parser()
    assert isinstance(parser, Parser)
    sub = next(a for a in parser._actions if hasattr(a, "choices") and a.choices)
    assert all(isinstance(p, Parser) for p in sub.choices.values())     # every command
    a = parser.parse_args(["beam", "--magnet-position", "20e-3", "2.5e-3", "-15.5e-3"])
    assert a.magnet_position == [20e-3, 2.5e-3, -15.5e-3]
    a = parser.parse_args(["rve", "--chain-direction", "-1e-3", "0", "-1"])
    assert a.chain_direction == [-1e-3, 0.0, -1.0]


def test_micron_mean_radius_takes_its_own_bounds(tmp_path, capsys):
    # the bounds used to stay at the seed's [10, 50] nm: "mean radius must lie strictly inside"
    assert main(["rve", "--phi", "0.10", "--n", "20", "--mean-radius", "1e-6", "--json",
                 str(tmp_path / "s.json")]) == 0
    d = json.loads((tmp_path / "s.json").read_text())
    cfg = d["manifest"]["config"]
    assert (cfg["r_min"], cfg["r_max"]) == pytest.approx((0.4e-6, 2e-6), rel=1e-15)
    r = d["summary"]["radius_m"]
    assert 0.4e-6 <= r["min"] and r["max"] <= 2e-6
    assert cfg["inputs"] == {} and cfg["outputs"] == {"json": str(tmp_path / "s.json")}
    # one bound given: the other still follows the radius
    assert main(["rve", "--n", "20", "--mean-radius", "1e-6", "--r-max", "3e-6", "--json",
                 str(tmp_path / "t.json")]) == 0
    cfg = json.loads((tmp_path / "t.json").read_text())["manifest"]["config"]
    assert (cfg["r_min"], cfg["r_max"]) == pytest.approx((0.4e-6, 3e-6), rel=1e-15)


def test_seed_paper_preset_is_the_old_default_bit_for_bit(tmp_path):
    base = ["rve", "--n", "150", "--seed", "5", "--B", "0.1"]
    assert main(base + ["--out", str(tmp_path / "a.h5"), "--json", str(tmp_path / "a.json")]) == 0
    assert main(base + ["--particle-material", "seed-paper", "--mean-radius", "25e-9",
                        "--r-min", "1e-8", "--r-max", "5e-8", "--gsd", "1.4",
                        "--core-density", "7870", "--rho-particle", "7870", "--sigma-s", "178",
                        "--out", str(tmp_path / "b.h5"), "--json",
                        str(tmp_path / "b.json")]) == 0
    assert RVE.load(tmp_path / "a.h5") == RVE.load(tmp_path / "b.h5")
    a, b = (json.loads((tmp_path / f).read_text()) for f in ("a.json", "b.json"))
    assert a["summary"] == b["summary"]                  # the magnetics too, bit for bit
    cfg = a["manifest"]["config"]
    assert (cfg["r_min"], cfg["r_max"], cfg["mean_radius"], cfg["gsd"]) == (10e-9, 50e-9, 25e-9,
                                                                             1.4)
    assert (cfg["core_density"], cfg["core_sigma"], cfg["shell"]) == (7870.0, None, 0.0)
    assert (cfg["rho_kg_m3"], cfg["sigma_s_Am2_kg"]) == (7870.0, 178.0)


def test_particle_material_presets_and_explicit_options_win(tmp_path):
    assert main(["rve", "--n", "40", "--particle-material", "carbonyl-iron", "--json",
                 str(tmp_path / "c.json")]) == 0
    d = json.loads((tmp_path / "c.json").read_text())
    assert d["summary"]["specific_moment_Am2_kg"] == pytest.approx(210.0)
    assert 0.4e-6 <= d["summary"]["radius_m"]["min"] and d["summary"]["radius_m"]["max"] <= 2e-6
    assert d["manifest"]["config"]["core_density"] == 7800.0
    assert main(["rve", "--n", "40", "--particle-material", "carbonyl-iron", "--core-sigma",
                 "200", "--mean-radius", "2e-6", "--json", str(tmp_path / "d.json")]) == 0
    d = json.loads((tmp_path / "d.json").read_text())
    assert d["summary"]["specific_moment_Am2_kg"] == pytest.approx(200.0)
    assert d["manifest"]["config"]["r_max"] == pytest.approx(4e-6, rel=1e-15)
    # magnetite: Fe3O4 core in the regime law, its own moment
    assert main(["rve", "--n", "30", "--particle-material", "magnetite", "--B", "0.1", "--json",
                 str(tmp_path / "m.json")]) == 0
    d = json.loads((tmp_path / "m.json").read_text())
    assert d["summary"]["specific_moment_Am2_kg"] == pytest.approx(92.0)
    assert d["manifest"]["config"]["sigma_s_Am2_kg"] == 92.0


def test_unknown_particle_material_exit_2(capsys):
    assert main(["rve", "--particle-material", "unobtainium"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mapsim rve: error:") and "carbonyl-iron" in err and "\n" not in err
