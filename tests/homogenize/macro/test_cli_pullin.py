"""``mapsim beam --magnet ... --gap-m / --gap-sweep-m``: the field on the deformed strip from the
command line (the solver itself: tests/homogenize/macro/test_pullin.py)."""
import json

import numpy as np
import pytest

from homogenize.cli import main

STRIP = ["beam", "--length-m", "20e-3", "--width-m", "5e-3", "--thickness-m", "1e-3"]
MAGNET = ["--magnet", "cylinder", "--magnet-size", "10e-3", "10e-3", "--remanence-T", "1.3"]


def test_far_gap_reproduces_the_dead_load_elastica(tmp_path, capsys):
    """At a 40 mm gap the strip hardly moves: the follower field equals the dead load of the
    undeformed strip, so the tip deflection equals the elastica under the dead-load force
    profile (same magnet placed by hand at the same place)."""
    j = tmp_path / "g.json"
    assert main(STRIP + MAGNET + ["--E-Pa", "2e6", "--gap-m", "0.04", "--json", str(j)]) == 0
    follower = json.loads(j.read_text())["pullin"]
    d_follow = follower["sweep_tip_deflection_m"][0]
    # the same magnet centred under the tip end, its top face 40 mm below the strip's face
    k = tmp_path / "d.json"
    assert main(STRIP + MAGNET + ["--E-Pa", "2e6", "--magnet-position", "20e-3", "2.5e-3",
                                  "-45e-3", "--model", "elastica", "--json", str(k)]) == 0
    d_dead = json.loads(k.read_text())["results"][0]["tip_m"]
    assert 0 < d_follow < 1e-4
    # discretizations differ (32 elastica segments against the BVP on 101 stations) and the
    # follower correction at 40 mm is ~1e-4 relative (test_pullin): within 1 %
    assert d_follow == pytest.approx(d_dead, rel=1e-2)


def test_sweep_reports_pull_in_and_release_with_a_figure(tmp_path, capsys):
    """A stiff strip (20 MPa) on a sweep 14 -> 4 mm and back: pull-in below release
    (hysteresis), zero tip gap and a positive contact force on the contact branch."""
    j, png = tmp_path / "s.json", tmp_path / "s.png"
    rc = main(STRIP + MAGNET + ["--E-Pa", "20e6", "--gap-sweep-m", "0.014:0.004:6", "--json",
                                str(j), "--png", str(png)])
    assert rc == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "pull-in gap" in out and "release gap" in out
    r = json.loads(j.read_text())
    p = r["pullin"]
    assert "bottom face" in r["gap_definition"]
    assert 0.004 < p["pull_in_gap_m"] < p["release_gap_m"] < 0.014
    # what the strip does, in words: it snaps into tip contact (no table: no interval)
    assert p["pull_in_lands_on"] == "tip contact" and r["interval_from"] is None
    assert any("snaps onto the magnet: its tip on the face" in x for x in r["what_happens"])
    assert "snaps onto the magnet: its tip on the face" in out
    br = np.array(p["sweep_branch"])
    on = br == "contact"
    assert on.any() and (br == "free").any()
    assert np.all(np.abs(np.array(p["sweep_tip_gap_m"])[on]) < 1e-9)
    assert np.all(np.array(p["sweep_contact_force_N"])[on] > 0)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_dead_load_through_the_magnet_is_warned(tmp_path, capsys):
    """The dead-load path (no --gap option) at a 3 mm gap bends the tip beyond the magnet's
    face: a warning names it and points to --gap-m."""
    rc = main(STRIP + MAGNET + ["--E-Pa", "2e6", "--magnet-position", "20e-3", "2.5e-3",
                                "-8e-3", "--model", "eb"])
    assert rc == 0
    err = capsys.readouterr().err
    assert "passes through the magnet" in err and "--gap-m" in err


@pytest.mark.parametrize("extra, words", [
    (["--gap-sweep-m", "0.01:0.01:3"], ("--gap-sweep-m", "differ")),
    (["--gap-sweep-m", "-0.01:0.005:3"], ("--gap-sweep-m", ">= 0")),
    (["--gap-sweep-m", "0.01:0.005"], ("--gap-sweep-m", "START:STOP:COUNT")),
    (["--gap-m", "-0.001"], ("--gap-m",)),
    (["--gap-m", "0.01", "--gap-sweep-m", "0.02:0.01:3"], ("--gap-m", "--gap-sweep-m")),
])
def test_bad_gaps_exit_2_nothing_written(extra, words, tmp_path, capsys):
    j = tmp_path / "x.json"
    rc = main(STRIP + MAGNET + ["--E-Pa", "2e6", "--json", str(j)] + extra)
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(w in err[0] for w in words), err
    assert list(tmp_path.iterdir()) == []


def test_gap_needs_a_permanent_magnet(tmp_path, capsys):
    assert main(STRIP + ["--E-Pa", "2e6", "--gap-m", "0.01"]) == 2
    assert "--magnet" in capsys.readouterr().err
    assert main(STRIP + ["--E-Pa", "2e6", "--magnet", "coil", "--magnet-size", "5e-3", "1e-2",
                         "--current-A", "1", "--turns", "100", "--gap-m", "0.01"]) == 2
    assert "permanent magnet" in capsys.readouterr().err


def test_interval_ends_pair_the_weak_pull_with_the_stiff_strip():
    """The ends of a pull-in interval: (E high, M low) gives the smallest gap, (E low, M high)
    the largest; without any interval only the mean; E's ends are the table's widened by the
    discretization error (Estimate.total_low / total_high)."""
    from homogenize.macro.pullin import interval_ends
    from homogenize.tables import Estimate
    E = Estimate(mean=2.0e6, ci_low=1.9e6, ci_high=2.1e6, se=4e4, dof=3.0, confidence=0.95,
                 unit="Pa", disc_err=0.05e6, has_disc=True)
    m, lo, hi = (lambda H: 1.0 * H), (lambda H: 0.9 * H), (lambda H: 1.1 * H)
    ends = interval_ends(E.mean, m, E, {"low": lo, "high": hi})
    assert ends["mean"] == (2.0e6, m)
    assert ends["low"] == (2.15e6, lo) and ends["high"] == (1.85e6, hi)
    assert interval_ends(2e6, m) == {"mean": (2e6, m)}
    only_E = interval_ends(E.mean, m, E)
    assert only_E["low"] == (2.15e6, m) and only_E["high"] == (1.85e6, m)


@pytest.mark.slow
def test_table_intervals_reach_the_pull_in_gap(tmp_path, capsys, synthetic_table):
    """With --table the pull-in gap carries the table's M_eff interval, and with --E-from-table
    its E_eff interval too (issue 35: intervals through every magnet case): the ends are
    (E high, M low) and (E low, M high), the mean lies between them, and the
    E_eff interval's ends are the table's, widened by its discretization error."""
    import os
    if not os.environ.get("MAPSIM_FULL"):
        pytest.skip("full version: MAPSIM_FULL=1 (three follower-elastica sweeps with contact "
                    "and release; minutes, and more than 6 min on a loaded 2-core machine)")
    from homogenize.tables import modulus_from_table, read_table
    table = synthetic_table(tmp_path / "t.h5", fem=True)
    E = modulus_from_table(read_table(table), 0.05)
    assert E is not None and E.total_low < E.mean < E.total_high
    sweep = ["--table", str(table), "--phi", "0.05", "--gap-sweep-m", "0.016:0.004:7"]
    j1 = tmp_path / "e.json"
    assert main(STRIP + MAGNET + sweep + ["--E-from-table", "--json", str(j1)]) == 0, \
        capsys.readouterr().err
    assert "M_eff and E_eff intervals" in capsys.readouterr().out
    both = json.loads(j1.read_text())
    assert both["E_Pa"] == pytest.approx(E.mean, rel=1e-12)
    assert both["interval_ends"]["low"]["E_Pa"] == pytest.approx(E.total_high, rel=1e-12)
    assert both["interval_ends"]["high"]["E_Pa"] == pytest.approx(E.total_low, rel=1e-12)
    lo, hi = both["interval"]["pull_in_gap_m"]
    assert lo < both["pullin"]["pull_in_gap_m"] < hi
