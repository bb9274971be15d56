"""The commands batch, compare and rve-size, run in-process against a loopback scheduler."""
import json

import numpy as np
from scipy.constants import mu_0
import pytest

from homogenize.cli import main
from homogenize.tables.batch import parts_dir_for, read_table




STUDY = """
[study]
name = "cli-test"
seed = 99
realizations = 10
n_particles = 100
evaluator = "synthetic"

[grid]
phi = 0.035
arrangement = ["dispersed", "chains"]
B_T = [0.05, 0.3]
gradB_T_per_m = 1.78

[rve_size]
n_particles = [25, 100, 400]
realizations = 8
quantity = "f_eff"
component = "z"
target_rel_precision = 0.02
"""


@pytest.fixture(scope="module")
def scheduler():
    """A Dask cluster on loopback TCP (threads in this process), reached via --scheduler."""
    from dask.distributed import LocalCluster
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp",
                      host="127.0.0.1", dashboard_address="127.0.0.1:0") as c:
        yield c.scheduler_address


@pytest.fixture(scope="module")
def table(scheduler, tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    (d / "study.toml").write_text(STUDY)
    out = d / "table.h5"
    rc = main(["batch", str(d / "study.toml"), "--out", str(out), "--scheduler", scheduler,
               "--no-progress"])
    assert rc == 0
    return out


@pytest.mark.parametrize("edit, words", [
    (("n_particles = 100", "n_particels = 100"), ["[study]", "unknown key", "n_particels"]),
    (("B_T = [0.05, 0.3]", "B_T = []"), ["[grid] B_T", "empty"]),
    (("realizations = 10", "realizations = -2"), ["realizations", "-2"]),
    (("n_particles = 100", "n_particles = -1"), ["n_particles", "-1"]),
])
def test_bad_study_file_exit_2_one_message_no_output(tmp_path, capsys, edit, words):
    p = tmp_path / "bad.toml"
    p.write_text(STUDY.replace(*edit))
    out = tmp_path / "t.h5"
    rc = main(["batch", str(p), "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and str(p) in lines[0], err
    for w in words:
        assert w in err
    assert list(tmp_path.iterdir()) == [p]        # neither table nor parts directory


def test_bad_options_exit_2(tmp_path, capsys):
    p = tmp_path / "s.toml"
    p.write_text(STUDY)
    assert main(["batch", str(p), "--out", str(tmp_path / "t.h5"), "--workers", "0"]) == 2
    assert "--workers" in capsys.readouterr().err
    assert main(["batch", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "t.h5")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert not (tmp_path / "t.h5").exists()


def test_batch_via_scheduler_writes_table(table):
    t = read_table(table)
    assert len(t.points) == 4 and t.values["f_eff_N_m3"].shape == (4, 10, 3)
    assert parts_dir_for(table).is_dir()


def test_compare_chains_vs_dispersed(table, tmp_path, capsys):
    js = tmp_path / "cmp.json"
    rc = main(["compare", str(table), "arrangement=dispersed,B_T=0.3",
               "arrangement=chains,B_T=0.3", "--quantity", "f_eff", "--json", str(js),
               "--permutations", "999"])
    out = capsys.readouterr().out
    assert rc == 0 and "Welch" in out and "permutation" in out and "Hedges" in out
    res = json.loads(js.read_text())
    t = read_table(table)
    a = t.select("arrangement=dispersed,B_T=0.3")
    b = t.select("arrangement=chains,B_T=0.3")
    vals = t.component_values("f_eff", "z")
    assert np.isclose(res["difference"], vals[b].mean() - vals[a].mean())
    # the synthetic chains force is 25 % higher, sd 5 %: effect size 5, with 10 + 10
    # realizations the expected t is 11 (power ~ 1 at p < 0.01)
    assert res["p_welch"] < 0.01 and res["p_permutation"] < 0.05 and res["hedges_g"] > 1
    # by index, the same result
    rc = main(["compare", str(table), str(a), str(b), "--json", str(js), "--permutations", "999"])
    assert rc == 0 and np.isclose(json.loads(js.read_text())["difference"], res["difference"])


@pytest.mark.parametrize("args, word", [
    (["0", "0"], "same grid point"),
    (["arrangement=dispersed", "1"], "matches 2 grid points"),
    (["7", "1"], "out of range"),
    (["phi=0.035,colour=red", "1"], "unknown axis"),
    (["0", "1", "--quantity", "g_eff"], "no quantity"),
    (["0", "1", "--component", "w"], "component"),
])
def test_compare_bad_points(table, capsys, args, word):
    rc = main(["compare", str(table), *args])
    assert rc == 2 and word in capsys.readouterr().err


def test_rve_size_recovers_kanit_exponent(scheduler, tmp_path, capsys):
    """The synthetic variance is exactly proportional to 1/V: alpha ~ 1; realizations needed
    grow as 1/V. Tolerance: sd of log s^2 with 8 realizations is sqrt(2/7) = 0.53 per size;
    over a factor 16 in V the slope's se is ~0.3, so |alpha - 1| < 1 is a 3-sigma band."""
    p = tmp_path / "s.toml"
    p.write_text(STUDY)
    assert main(["rve-size", str(p), "--out", str(tmp_path / "rs"), "--at", "B_T=0.7"]) == 2
    assert "not a grid value" in capsys.readouterr().err
    rc = main(["rve-size", str(p), "--out", str(tmp_path / "rs"), "--scheduler", scheduler,
               "--no-progress", "--at", "B_T=0.3,arrangement=dispersed"])
    assert rc == 0
    res = json.loads((tmp_path / "rs" / "rve_size.json").read_text())
    assert len(res["points"]) == 1
    row = res["points"][0]
    assert row["point"]["B_T"] == 0.3 and row["point"]["arrangement"] == "dispersed"
    assert abs(row["alpha"] - 1.0) < 1.0
    need = [s["realizations_needed_fit"] for s in row["sizes"]]
    assert need[0] > need[1] > need[2]
    # rel sd 0.05 sqrt(100/n): at n = 25 it is 0.1 -> (1.96 * 0.1 / 0.02)^2 ~ 96 realizations
    assert 40 < row["sizes"][0]["realizations_needed"] < 400
    assert (tmp_path / "rs" / "rve_size.png").stat().st_size > 1000
    assert "alpha" in capsys.readouterr().out


def test_default_study_file_is_valid():
    from homogenize.studies.chain import DEFAULT_STUDY
    from homogenize.tables._study import load_study
    s = load_study(DEFAULT_STUDY)
    assert s.evaluator == "rve" and dict(s.axes)["phi"] == (0.0175, 0.035)
    assert dict(s.axes)["gradB_T_per_m"] == (1.78,)
    # sized for a few minutes on 2 cores (~0.5 s per 200-particle RVE on one core)
    assert len(s.tasks()) * 0.5 / 2 < 180


def test_chain_reduced_real_rves(scheduler, tmp_path):
    """The whole chain on a reduced study of real RVEs (particles -> dipoles -> beam)."""
    from homogenize.studies.chain import SEED, seed_strip
    p = tmp_path / "chain.toml"
    p.write_text('[study]\nseed = 3\nrealizations = 3\nn_particles = 40\n'
                 '[grid]\nphi = [0.0175, 0.035]\nB_T = [0.01, 0.3]\ngradB_T_per_m = 1.78\n')
    out = tmp_path / "chain"
    assert main(["chain", str(p), "--out", str(out), "--scheduler", scheduler,
                 "--no-progress"]) == 0
    res = json.loads((out / "chain.json").read_text())
    assert (out / "deflection_vs_B.png").stat().st_size > 1000
    assert "phi = 0.035" in (out / "summary.md").read_text()
    assert (out / "table.h5").exists() and not parts_dir_for(out / "table.h5").exists()
    strip = seed_strip()
    # the strip satisfies the paper's premise: EB deflection 4 mm at 43.79 kN/m^3
    L, t = strip["length_m"], strip["thickness_m"]
    assert np.isclose(1.5 * SEED["f_paper_N_m3"] * L ** 4 / (2e6 * t ** 2), 4e-3, rtol=1e-12)
    t_tab = read_table(out / "table.h5")
    for c in res["curves"]:
        for g in c["grid"]:
            # chain.json holds 6 significant digits (micro.common.files.RESULT_DIGITS): each value is
            # within 5e-7 (relative) of the computed one, a ratio of two within 1e-6
            # EB deflection is 4 mm x f / 43.79 kN/m^3 (linear, geometry-independent) ...
            assert np.isclose(g["deflection_eb_m"], 4e-3 * g["f_eff_N_m3"] / 43.79e3, rtol=2e-6)
            # ... the elastica is below it (a dead load bends less at large rotation) ...
            assert g["deflection_elastica_m"] <= g["deflection_eb_m"] * (1 + 2e-6)
            # ... and the force at a grid point is that point's mean in the table
            i = t_tab.select(f"phi={c['phi']!r},B_T={g['B_internal_T']!r}")
            assert np.isclose(g["f_eff_N_m3"], t_tab.values["f_eff_N_m3"][i, :, 2].mean())
            # ... and the applied field exceeds the internal one by mu0 N M_eff (strip demag)
            # (a difference of two rounded values: absolute error <= 5e-7 (|B_a| + |B_in|))
            assert np.isclose(g["B_applied_T"] - g["B_internal_T"],
                              mu_0 * res["demag_factor"] * g["M_eff_A_per_m"], rtol=2e-6,
                              atol=1e-6 * (g["B_applied_T"] + g["B_internal_T"]))
        # the magnet experiment: the closer the magnet, the larger the deflection
        tips = [r["deflection_elastica_m"] for r in c["magnet_sweep"] if "outside_table" not in r]
        assert len(tips) >= 3 and all(a > b for a, b in zip(tips, tips[1:]))
    # Aharoni's factor of the 19.4 x 5 x 1 mm strip through its thickness (0.771)
    assert 0.76 < res["demag_factor"] < 0.78 and res["law"] == "regime"
    assert (out / "deflection_vs_magnet_gap.png").stat().st_size > 1000
    # the follower field (issue 35): a pull-in gap inside its interval, or why not
    for c in res["curves"]:
        p = c["pullin"]
        if p["available"]:
            lo, hi = p["pull_in_gap_ci_m"]
            assert lo <= p["pull_in_gap_m"] <= hi
            assert {r["branch"] for r in p["closing"]} <= {"free", "contact", "unmodelled"}
        else:       # this reduced table ends at 0.3 T: the path may leave it; said why
            assert p["why"]
    # dilute limit: the force per particle volume hardly depends on phi (interactions at
    # 1.75-3.5 vol% change it by a few %), so doubling phi doubles the force within 10 %
    f = {c["phi"]: c["grid"][0]["f_eff_N_m3"] for c in res["curves"]}
    assert 1.8 < f[0.035] / f[0.0175] < 2.2


def test_beam_with_table_propagates_interval(table, tmp_path, capsys):
    """`mapsim beam --table`: the force and its interval come from the table; with
    Euler-Bernoulli the deflection is 3 f L^4 / (2 E t^2) at the mean and at both ends."""
    from homogenize.tables.batch import body_force_from_table
    js = tmp_path / "beam.json"
    L, t = 0.02, 1e-3
    rc = main(["beam", "--table", str(table), "--phi", "0.035", "--B", "0.1", "--gradB", "3.56",
               "--at", "arrangement=dispersed", "--model", "eb", "elastica",
               "--length-m", str(L), "--thickness-m", str(t), "--json", str(js)])
    assert rc == 0, capsys.readouterr().err
    res = json.loads(js.read_text())
    f = body_force_from_table(table, 0.035, 0.1, 3.56, arrangement="dispersed")
    eb = next(r for r in res["results"] if r["model"] == "eb")
    for key, force in (("tip_m", f.mean), ("ci_low_m", f.ci_low), ("ci_high_m", f.ci_high)):
        assert np.isclose(eb[key], 1.5 * force * L ** 4 / (2e6 * t ** 2), rtol=1e-9)
    el = next(r for r in res["results"] if r["model"] == "elastica")
    assert el["ci_low_m"] < el["tip_m"] < el["ci_high_m"] and el["tip_m"] <= eb["tip_m"]
    # the table's gradient is 1.78 T/m: the force was scaled linearly to 3.56 T/m
    f0 = body_force_from_table(table, 0.035, 0.1, 1.78, arrangement="dispersed")
    assert np.isclose(f.mean, 2 * f0.mean, rtol=1e-12)
    capsys.readouterr()
    assert main(["beam", "--table", str(table), "--B", "0.1", "--gradB", "1.78"]) == 2
    assert "--phi is required" in capsys.readouterr().err
    assert main(["beam", "--table", str(table), "--phi", "0.035", "--B", "0.1", "--gradB",
                 "1.78"]) == 2
    assert "give arrangement" in capsys.readouterr().err
    assert main(["beam", "--table", str(table), "--phi", "0.035", "--B", "0.1", "--gradB",
                 "1.78", "--at", "arrangement=dispersed", "--E-from-table"]) == 2
    assert "no E_eff" in capsys.readouterr().err


def test_fem_quantities_in_table_and_beam_E_from_table(scheduler, tmp_path, capsys):
    """With fem = true the table holds E_eff, nu_eff, stress_mag and strain_mag (synthetic
    values here: the FEM itself is tested by its own module); `beam --E-from-table` uses E_eff
    and widens the interval by its relative half-width in quadrature."""
    from homogenize.tables.batch import body_force_from_table, modulus_from_table
    p = tmp_path / "fem.toml"
    p.write_text('[study]\nseed = 8\nrealizations = 5\nevaluator = "synthetic"\nfem = true\n'
                 '[grid]\nphi = 0.035\nB_T = [0.05, 0.3]\ngradB_T_per_m = 1.78\n')
    out = tmp_path / "fem.h5"
    assert main(["batch", str(p), "--out", str(out), "--scheduler", scheduler,
                 "--no-progress"]) == 0
    t = read_table(out)
    assert t.units["E_eff_Pa"] == "Pa" and t.units["nu_eff"] == "1"
    assert t.values["stress_mag_Pa"].shape == (2, 5, 3, 3)
    assert t.values["strain_mag"].shape == (2, 5, 3, 3)
    js = tmp_path / "b.json"
    L, th = 0.02, 1e-3
    assert main(["beam", "--table", str(out), "--phi", "0.035", "--B", "0.1", "--gradB", "1.78",
                 "--model", "eb", "--E-from-table", "--length-m", str(L), "--thickness-m",
                 str(th), "--json", str(js)]) == 0
    res = json.loads(js.read_text())["results"][0]
    f = body_force_from_table(out, 0.035, 0.1, 1.78)
    E = modulus_from_table(out, 0.035)
    # E of both B points pooled: 10 realizations
    assert np.isclose(E.mean, t.values["E_eff_Pa"].mean())
    assert np.isclose(res["tip_m"], 1.5 * f.mean * L ** 4 / (E.mean * th ** 2), rtol=1e-9)
    rel_f = (f.ci_high - f.mean) / f.mean
    rel_E = (E.ci_high - E.ci_low) / (2 * E.mean)
    assert np.isclose(res["ci_high_m"] / res["tip_m"] - 1, np.hypot(rel_f, rel_E), rtol=1e-9)


def test_export_from_table(table, tmp_path, capsys):
    from homogenize.macro.exporters import parse_abaqus
    from homogenize.tables.batch import body_force_from_table
    f = body_force_from_table(table, 0.035, 0.3, 1.78, arrangement="chains")
    for bound, value in (("mean", f.mean), ("low", f.ci_low), ("high", f.ci_high)):
        out = tmp_path / f"{bound}.inp"
        assert main(["export", "--to", "abaqus", "--table", str(table), "--phi", "0.035",
                     "--B", "0.3", "--gradB", "1.78", "--at", "arrangement=chains",
                     "--bound", bound, "--out", str(out)]) == 0
        spec = parse_abaqus(out.read_text())
        assert np.allclose(spec["body_force_N_m3"], [0, 0, -value], rtol=1e-12)   # along -z
        # mixture density (1 - phi) 1210 + phi 7870 kg/m^3; PDMS E, nu (no FEM in the table)
        assert np.isclose(spec["density_kg_m3"], 0.965 * 1210 + 0.035 * 7870)
        assert spec["E_Pa"] == 2e6 and spec["nu"] == 0.45
    # a matrix preset: its E and nu where the table has no FEM, the mixture with its density
    out = tmp_path / "sylgard.inp"
    assert main(["export", "--to", "abaqus", "--table", str(table), "--phi", "0.035",
                 "--B", "0.3", "--gradB", "1.78", "--at", "arrangement=chains",
                 "--matrix-material", "sylgard184-10to1", "--out", str(out)]) == 0
    spec = parse_abaqus(out.read_text())
    assert np.isclose(spec["density_kg_m3"], 0.965 * 1030 + 0.035 * 7870)
    assert spec["E_Pa"] == 2.0e6 and spec["nu"] == 0.49
    capsys.readouterr()
    assert main(["export", "--to", "elmer", "--E-Pa", "2e6", "--nu", "0.45", "--out", "-"]) == 2
    assert "--body-force-N-m3 is required" in capsys.readouterr().err


def _sigint_as_from_a_terminal():
    """In the child before exec: SIGINT back to its default action. A test run started as a
    background job of a non-interactive shell inherits SIGINT ignored, and Python then installs
    no KeyboardInterrupt handler, so the batch would run to its end (as it should under nohup);
    the test is about a Ctrl-C in a terminal."""
    import signal
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_on_the_command_then_rerun_resumes(scheduler, tmp_path):
    """A real `mapsim batch` process (local cluster of worker processes) gets SIGINT after a
    few realizations: it exits 130 leaving only whole results; the rerun computes exactly the
    missing realizations, and the table holds each realization's own values."""
    import signal
    import subprocess
    import sys
    import time

    from homogenize.tables._evaluate import SyntheticEvaluator
    from homogenize.tables._study import load_study
    from homogenize.tables.batch import run_batch
    p = tmp_path / "s.toml"
    p.write_text('[study]\nseed = 4\nrealizations = 6\nevaluator = "synthetic"\n'
                 '[grid]\nphi = 0.035\nB_T = [0.01, 0.1, 0.5]\ngradB_T_per_m = 1.78\n'
                 '[synthetic]\nwork_seconds = 0.3\n')
    out = tmp_path / "t.h5"
    parts = parts_dir_for(out)
    proc = subprocess.Popen([sys.executable, "-m", "homogenize.cli", "batch", str(p), "--out",
                             str(out), "--workers", "1", "--no-progress"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_sigint_as_from_a_terminal)
    try:
        t_end = time.monotonic() + 300          # bounded wait (cluster start-up on a busy box)
        while time.monotonic() < t_end and proc.poll() is None:
            if parts.is_dir() and len(list(parts.glob("*.npz"))) >= 2:
                break
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        _out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "interrupted" in err and not out.exists()
    stored = {f.name.split("_")[0] + "_" + f.name.split("_")[1] for f in parts.glob("*.npz")}
    assert 2 <= len(stored) < 18 and not list(parts.glob(".*.tmp"))
    calls = tmp_path / "calls"
    calls.mkdir()
    study = load_study(p)
    run_batch(study, out, evaluator=SyntheticEvaluator(counter_dir=str(calls)),
              scheduler=scheduler, progress=False)
    redone = {"g%05d_r%04d" % (int(c.name.split("_")[0][1:]), int(c.name.split("_")[1][1:]))
              for c in calls.iterdir()}
    assert len(list(calls.iterdir())) == 18 - len(stored)      # each missing one, once
    assert not redone & stored
    t = read_table(out)
    for task in study.tasks():
        assert np.array_equal(t.values["f_eff_N_m3"][task.grid_index, task.realization],
                              SyntheticEvaluator()(task)["f_eff_N_m3"])


def test_specimen_with_the_table_law(table, tmp_path, capsys):
    """mapsim specimen --law table: the composite's M(H_in) from a batch table's M_eff, the
    same nodes as the beam's magnetization_from_table, never extrapolated."""
    from homogenize.macro.effective import magnetization_from_table, magnetization_table_law
    t = read_table(table)
    law = magnetization_table_law(t, 0.035, arrangement="dispersed")
    f = magnetization_from_table(t, 0.035, arrangement="dispersed")
    H = np.asarray(law.H_nodes_A_per_m)
    # identical nodes (both read the same interpolated table values): round-off only
    assert np.allclose(law.M_A_per_m(H), f(H), rtol=1e-12, atol=0)
    lo = magnetization_table_law(t, 0.035, bound="low", arrangement="dispersed")
    hi = magnetization_table_law(t, 0.035, bound="high", arrangement="dispersed")
    assert np.all(np.asarray(lo.M_nodes_A_per_m) <= np.asarray(hi.M_nodes_A_per_m))
    def specimen(B, out):
        return main(["specimen", "--shape", "sphere", "--radius-m", "1e-3", "--law", "table",
                     "--table", str(table), "--at", "arrangement=dispersed", "--phi", "0.035",
                     "--shear-modulus-Pa", "1e3", "--B", B, "--n-mesh", "3", "--n-boundary",
                     "24", "--json", str(out), "--quiet"])
    out = tmp_path / "s.json"
    rc = specimen("0.1,0.2", out)
    assert rc == 0, capsys.readouterr().err
    res = json.loads(out.read_text())
    M = [s["M_mean_A_per_m"] for s in res["steps"]]
    # a sphere's internal field is H0 - M/3 < H0: M below the table's M at the applied field
    assert 0 < M[0] < M[1] <= law.M_A_per_m(np.array([0.2 / mu_0]))[0]
    # beyond the table's field range: refused, not extrapolated (exit 2), nothing written
    out2 = tmp_path / "t.json"
    rc = specimen("0.5", out2)
    assert rc == 2 and not out2.exists()
    assert "table" in capsys.readouterr().err


def test_batch_summary_prints_every_quantity_with_its_interval(tmp_path, capsys):
    """The batch summary: mean and interval of every quantity, E_eff too (issue 36; it
    printed f_eff_z only). Parts made in-process: the batch finds them all and needs no Dask."""
    from homogenize.tables._evaluate import get_evaluator
    from homogenize.tables._study import parse_study
    from homogenize.tables.batch import _part_path, _write_part
    text = STUDY.split("[rve_size]")[0].replace('evaluator = "synthetic"',
                                                'evaluator = "synthetic"\nfem = true')
    (tmp_path / "s.toml").write_text(text)
    out = tmp_path / "t.h5"
    study = parse_study(text, str(tmp_path / "s.toml"))
    ev = get_evaluator("synthetic")
    for t in study.tasks():
        k = t.key(ev.id)
        _write_part(_part_path(parts_dir_for(out), t, k), t, k, ev(t))
    capsys.readouterr()
    assert main(["batch", str(tmp_path / "s.toml"), "--out", str(out), "--no-progress"]) == 0
    lines = capsys.readouterr().out.splitlines()
    tab = read_table(out)
    for q in tab.values:
        head = [ln for ln in lines if f" {q}" in ln and "95 % interval" in ln]
        assert len(head) == 1, q
        i = lines.index(head[0])
        rows = lines[i + 1:i + 1 + len(tab.points)]
        assert all(r.rstrip().endswith("]") and "[" in r for r in rows), q
    assert any("E_eff_Pa [Pa]" in ln for ln in lines)
    assert any("f_eff_N_m3_z [N/m^3]" in ln for ln in lines)
