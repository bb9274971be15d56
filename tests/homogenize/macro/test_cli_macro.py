"""The macro commands through homogenize.cli.main: output, files, bad input -> exit 2."""
import json

import pytest

from homogenize.cli import main
from homogenize.macro.exporters import parse_abaqus, parse_elmer


def test_beam_prints_models(capsys, tmp_path):
    out = tmp_path / "beam.json"
    rc = main(["beam", "--model", "eb", "timoshenko", "fem", "--nz", "1", "--json", str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "timoshenko" in text and "fem" in text
    res = json.loads(out.read_text())["results"]
    assert res[0]["tip_m"] == pytest.approx(3 * 4e4 * 0.02**4 / (2 * 2e6 * 1e-3**2))


@pytest.mark.parametrize("to,parse", [("elmer", parse_elmer), ("abaqus", parse_abaqus)])
def test_export_writes_file(tmp_path, capsys, to, parse):
    out = tmp_path / f"snippet.{to}"
    rc = main(["export", "--to", to, "--body-force-N-m3", "43636.8", "--E-Pa", "2e6",
               "--nu", "0.45", "--density-kg-m3", "1443.1", "--out", str(out)])
    assert rc == 0
    p = parse(out.read_text())
    assert p["E_Pa"] == 2e6 and p["body_force_N_m3"][2] == -43636.8


def test_channel_command(capsys):
    assert main(["channel", "--a-m", "2e-3", "--nc", "1", "--d-m", "4e-3"]) == 0
    assert "max_deflection_m" in capsys.readouterr().out


@pytest.mark.parametrize("argv,word", [
    (["beam", "--length-m", "-1", "--model", "eb"], "--length-m"),
    (["beam", "--nu", "0.5", "--model", "eb"], "nu"),
    (["channel", "--c-m", "0"], "--c-m"),
    (["export", "--to", "elmer", "--body-force-N-m3", "1", "--E-Pa", "2e6", "--nu", "0.7",
      "--density-kg-m3", "1000", "--out", "-"], "nu"),
])
def test_bad_input_exit_2_one_line(argv, word, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and word in err and "Traceback" not in err


def test_missing_option_exit_2(capsys):
    # main() returns argparse's usage-error code instead of raising SystemExit
    assert main(["export", "--to", "abaqus", "--E-Pa", "2e6"]) == 2
    assert "required" in capsys.readouterr().err


def test_export_refuses_directory(tmp_path, capsys):
    rc = main(["export", "--to", "abaqus", "--body-force-N-m3", "1", "--E-Pa", "2e6", "--nu",
               "0.45", "--density-kg-m3", "1000", "--out", str(tmp_path)])
    assert rc == 2 and "directory" in capsys.readouterr().err


def test_channel_flow_and_target_gap(tmp_path, capsys):
    """`mapsim channel` with a flow: the coupled flow and the body force for a target gap; with
    a table, the applied field that gives that force (monotone inversion of the table)."""
    import json as _json
    out = tmp_path / "ch.json"
    q = 1.6667e-10                                        # 10 uL/min
    assert main(["channel", "--flow-rate-m3-s", str(q), "--target-gap-m", "30e-6",
                 "--json", str(out), "--png", str(tmp_path / "ch.png")]) == 0
    d = _json.loads(out.read_text())
    # mass conservation: the imposed flow rate is the flow through the channel
    assert d["flow"]["flow_rate_m3_s"] == pytest.approx(q, rel=1e-9)
    # the smallest gap sits at the target, at the outlet, and the body force pulls downwards
    assert d["target_gap"]["flow"]["min_gap_overall_m"] == pytest.approx(30e-6, rel=1e-3)
    assert d["target_gap"]["body_force_N_m3"] > 0
    assert (tmp_path / "ch.png").read_bytes()[:4] == b"\x89PNG"
    # bad input: both operating points, a target without flow
    assert main(["channel", "--flow-rate-m3-s", str(q), "--pressure-drop-Pa", "10"]) == 2
    assert main(["channel", "--target-gap-m", "30e-6"]) == 2


# --------------------------------------------------------------------------- issue 36


def test_channel_prints_what_was_asked_with_the_field_interval(tmp_path, capsys,
                                                                synthetic_table):
    table = synthetic_table(tmp_path / "t.h5")
    out = tmp_path / "ch.json"
    assert main(["channel", "--flow-rate-m3-s", "1.6667e-10", "--target-gap-m", "30e-6",
                 "--table", str(table), "--phi", "0.05", "--gradB", "30", "--nc", "1",
                 "--json", str(out)]) == 0
    text = capsys.readouterr().out
    # no JSON block of the dry ceiling at the default 40 kN/m^3 (a case not asked for)
    assert "f_N_m3" not in text and "pressure_Pa" not in text and "{" not in text
    assert text.startswith("target smallest gap 3e-05 m") and "% interval [" in text
    d = json.loads(out.read_text())
    lo, hi = d["target_gap"]["field_interval_T"]
    assert lo < d["target_gap"]["field"] < hi and "result" not in d
    assert d["manifest"]["config"]["inputs"] == {"table": str(table)}
    # without a table: the manifest lists no input (it listed ["table"])
    assert main(["channel", "--a-m", "2e-3", "--nc", "1", "--d-m", "4e-3", "--json",
                 str(out)]) == 0
    assert '"max_deflection_m"' in capsys.readouterr().out        # the asked dry case
    cfg = json.loads(out.read_text())["manifest"]["config"]
    assert cfg["inputs"] == {} and cfg["outputs"] == {"json": str(out)}
    assert (cfg["E_Pa"], cfg["nu"], cfg["density_kg_m3"]) == (2e6, 0.45, 1210.0)


def test_matrix_material_in_beam_and_channel(tmp_path, capsys):
    def tip(*extra):
        out = tmp_path / "b.json"
        assert main(["beam", "--model", "eb", "--json", str(out), *extra]) == 0
        d = json.loads(out.read_text())
        return d["results"][0]["tip_m"], d["material"]
    t0, m0 = tip()
    t1, m1 = tip("--matrix-material", "seed-paper", "--E-Pa", "2e6", "--nu", "0.45")
    assert t0 == t1 and m0 == m1 == {"E_Pa": 2e6, "nu": 0.45, "density_kg_m3": 1210.0}
    t2, m2 = tip("--matrix-material", "sylgard184-20to1")
    assert m2 == {"E_Pa": 1e6, "nu": 0.49, "density_kg_m3": 1030.0}
    assert t2 == pytest.approx(2 * t0)                     # Euler-Bernoulli: 1 / E
    t3, m3 = tip("--matrix-material", "sylgard184-20to1", "--E-Pa", "4e6")
    assert m3["E_Pa"] == 4e6 and m3["density_kg_m3"] == 1030.0
    assert main(["channel", "--matrix-material", "ecoflex", "--nc", "1"]) == 2
    assert "--matrix-material" in capsys.readouterr().err


def test_beam_magnet_below_the_strip_negative_scientific_notation(capsys):
    assert main(["beam", "--model", "eb", "--magnet", "cuboid", "--magnet-size", "1e-2", "1e-2",
                 "1e-2", "--remanence-T", "1.3", "--magnet-position", "20e-3", "2.5e-3",
                 "-15.5e-3", "--particle-material", "carbonyl-iron"]) == 0
    text = capsys.readouterr().out
    assert "(0.02, 0.0025, -0.0155)" in text and "carbonyl-iron" in text
