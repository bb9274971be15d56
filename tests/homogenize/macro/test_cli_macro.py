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
