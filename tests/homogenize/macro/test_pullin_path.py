"""What the strip does along the pull-in path (homogenize.macro.pullin, issue 35): the state it
snaps into at pull-in, where it lets go, and the evaluation budget that ends a path that cannot
be followed with the last converged state named (exit 3 from the CLI)."""
import functools
import json

import numpy as np
import pytest

from homogenize.macro.cantilever import Strip
from homogenize.macro.magnets import PermanentMagnet, linear_magnetization
from homogenize.macro.pullin import PathBudgetError, place_magnet, pullin_sweep
from micro.common.validate import ConvergenceError, InputError
from micro.demag import prism_demag_factors
from micro.materials import FE, ElasticMaterial

STRIP = Strip(20e-3, 5e-3, 1e-3)
L, T = STRIP.length_m, STRIP.thickness_m
M_OF_H = linear_magnetization(0.1, 0.03 * FE.Ms_A_m)
NZ = prism_demag_factors(20e-3, 5e-3, 1e-3)[2]
MAGNET = PermanentMagnet("cylinder", (10e-3, 10e-3), 1.3)
STIFF = ElasticMaterial(20e6, 0.45, 1210.0)


@pytest.fixture(scope="module")
def table_law(tmp_path_factory, synthetic_table):
    """M_eff(H) of the synthetic table at phi = 0.05 (the CLI case of the issue: mapsim beam
    --table T --phi 0.05 --E-Pa 2.2496e6 --gap-sweep-m 0.016:0.004:7)."""
    from homogenize.macro.effective import magnetization_from_table
    from homogenize.tables.batch import read_table
    t = synthetic_table(tmp_path_factory.mktemp("tab") / "t.h5", fem=True)
    return magnetization_from_table(read_table(t), 0.05)


def test_pull_in_into_a_free_bent_state_then_touch_then_lift_off(table_law):
    """The issue's CLI case (2.25 MPa, the table's M_eff; 16 segments, n_cross 2 to be quick):
    the free branch folds twice (pull-in ~13.4 mm, then back at ~14.7 mm), and between its
    touch point (~12.35 mm) and the second fold a stable free state exists with the tip
    beside the magnet's rim. At pull-in the strip snaps into THAT state (the only other stable
    state at the pull-in gap): a large deflection without contact. Closing further its tip
    touches the face without a snap; opening, it lifts off where it touched (contact force
    zero) -- below the pull-in gap, which is no contradiction: it never snapped into contact --
    and returns to the small deflection at the second fold, above the pull-in gap (the
    hysteresis loop is pull-in -> snap back)."""
    from homogenize.cli._pullin import describe
    mat = ElasticMaterial(2.2496e6, 0.45, 1210.0)
    gaps = np.array([16e-3, 14e-3, 13e-3, 12e-3, 10.5e-3])
    r = pullin_sweep(STRIP, mat, place_magnet(MAGNET, STRIP, 16e-3), table_law, gaps,
                     n_segments=16, n_cross=2, demag_factor=NZ)
    assert r.snap and 13e-3 < r.pull_in_gap_m < 14e-3
    assert r.pull_in_lands_on == "free" and r.landing_n_contact == 0
    assert r.landing_tip_gap_m > 0.5 * T                      # clearly off the face (1.3 mm)
    assert r.landing_tip_deflection_m > 3 * r.pull_in_tip_deflection_m
    # touch below the pull-in gap, no snap there: the lift-off is at the touch point
    assert r.touch_gap_m < r.pull_in_gap_m
    assert r.release_by == "contact force zero"
    assert r.release_gap_m == pytest.approx(r.touch_gap_m, rel=1e-9)
    # the strip returns to the small deflection above the pull-in gap: the loop closes
    assert r.snap_back_gap_m > r.pull_in_gap_m
    # ... at the second fold, located: the largest gap of the free branch past pull-in (not
    # the continuation step before it, which is what round-off on the fold's stability gave)
    free = np.flatnonzero(r.branch == "free")
    k_pull = free[np.argmin(np.abs(r.gap_m[free] - r.pull_in_gap_m))]
    assert r.snap_back_gap_m == pytest.approx(r.gap_m[free[free > k_pull]].max(), rel=1e-12)
    # the sweep follows it: at 13 mm (below pull-in, above the touch) bent and free; at 14 mm
    # closing small, opening still bent (between pull-in and snap back)
    n = len(gaps)
    k13 = 2
    assert r.sweep_branch[k13] == "free" and r.sweep_tip_deflection_m[k13] > 10e-3
    assert r.sweep_tip_deflection_m[1] < 3e-3                  # 14 mm, closing
    k14_back = 2 * n - 1 - 1 - 1                               # 14 mm, opening
    assert r.sweep_gap_m[k14_back] == pytest.approx(14e-3)
    assert r.sweep_branch[k14_back] == "free" and r.sweep_tip_deflection_m[k14_back] > 10e-3
    c = r.sweep_branch == "contact"
    assert np.all(r.sweep_gap_m[c] < r.touch_gap_m)
    # the words say the same
    text = " ".join(describe(r))
    assert "WITHOUT touching" in text and "touches the face at" in text
    assert "snaps back to the small deflection" in text and "release gap" in text


def test_stiff_strip_snaps_into_tip_contact_and_releases_above_pull_in():
    """20 MPa: the fold of the free branch has no other free state beside it; the strip snaps
    onto the magnet, its tip on the face, and releases at a larger gap (release >= pull-in on
    the branch it is on)."""
    from homogenize.cli._pullin import describe
    gaps = np.linspace(12e-3, 6e-3, 4)
    r = pullin_sweep(STRIP, STIFF, place_magnet(MAGNET, STRIP, 12e-3), M_OF_H, gaps,
                     n_segments=16, n_cross=2, demag_factor=NZ)
    assert r.snap and r.pull_in_lands_on == "tip contact" and r.landing_n_contact == 1
    assert r.landing_contact_force_N > 0 and abs(r.landing_tip_gap_m) < 1e-9 * L
    assert r.release_gap_m >= r.pull_in_gap_m
    text = " ".join(describe(r))
    assert "snaps onto the magnet: its tip on the face" in text
    assert "lifts off the face" in text


def test_tiny_budget_ends_in_convergence_error_naming_the_last_converged_state():
    """A path whose budget runs out ends in PathBudgetError (a ConvergenceError: exit 3),
    with the last converged state named: the loop it was in, the gap, the shape."""
    mag = place_magnet(MAGNET, STRIP, 12e-3)
    gaps = np.linspace(12e-3, 6e-3, 3)
    kw = dict(n_segments=8, n_cross=1, demag_factor=NZ)
    with pytest.raises(PathBudgetError) as e:
        pullin_sweep(STRIP, STIFF, mag, M_OF_H, gaps, max_evaluations=25, **kw)
    assert isinstance(e.value, ConvergenceError)
    last = e.value.last_converged
    assert "last converged state" in str(e.value) and "last converged state" in last["what"]
    assert last["stage"] == "the free branch from the far gap"
    assert last["evaluations"] == 26 and last["max_evaluations"] == 25
    assert gaps[-1] < last["gap_m"] and len(last["theta_rad"]) == 9
    assert 0 < last["tip_deflection_m"] < last["gap_m"] and last["contact_force_N"] == 0
    # a budget that lasts past the free branch: it ends in a later loop, at a smaller gap
    full = pullin_sweep(STRIP, STIFF, mag, M_OF_H, gaps, **kw)
    assert 0 < full.evaluations
    with pytest.raises(PathBudgetError) as e2:
        pullin_sweep(STRIP, STIFF, mag, M_OF_H, gaps, max_evaluations=full.evaluations - 3,
                     **kw)
    last2 = e2.value.last_converged
    assert last2["stage"] != "the free branch from the far gap"
    assert last2["gap_m"] >= gaps[-1] * (1 - 1e-9) and last2["tip_deflection_m"] > 0
    with pytest.raises(InputError, match="max_evaluations"):
        pullin_sweep(STRIP, STIFF, mag, M_OF_H, gaps, max_evaluations=0, **kw)


def test_cli_budget_exit_3_writes_the_last_converged_state(tmp_path, capsys, monkeypatch):
    """mapsim beam --gap-sweep-m with a path that cannot be followed (here: a budget of 30
    evaluations): exit 3, the JSON holds 'last_converged' (named as such) and the message
    names it."""
    import homogenize.cli._pullin as cp
    from homogenize.cli import main
    monkeypatch.setattr(cp, "pullin_sweep", functools.partial(pullin_sweep, max_evaluations=30))
    j = tmp_path / "x.json"
    rc = main(["beam", "--length-m", "20e-3", "--width-m", "5e-3", "--thickness-m", "1e-3",
               "--magnet", "cylinder", "--magnet-size", "10e-3", "10e-3", "--remanence-T", "1.3",
               "--E-Pa", "20e6", "--gap-sweep-m", "0.012:0.006:3", "--json", str(j)])
    assert rc == 3
    cap = capsys.readouterr()
    assert "last converged state" in cap.err and "budget" in cap.err
    assert "last_converged" in cap.out
    d = json.loads(j.read_text())
    assert d["status"] == "did not converge"
    lc = d["last_converged"]
    assert "last converged state" in lc["what"] and lc["gap_m"] > 0.006
    assert len(lc["theta_rad"]) == len(lc["s_m"])
