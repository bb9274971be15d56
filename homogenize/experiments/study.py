"""``diagnose-study``: how often does ``diagnose`` name the hidden cause?

Runs :func:`~homogenize.experiments.diagnose.diagnose` on ``n`` synthetic experiments cycling
through :data:`~homogenize.experiments.synthetic.CASES` (seeds ``seed, seed+1, ...``) and
reports the confusion matrix (expected causes x named causes, ``none`` for an empty set), the
rate of false causes (cases naming a cause that is not in the truth), the rate of exact
recoveries and the median gain of the cases with a hidden cause. Cases whose expected cause
cannot be tested because the project module behind it has not landed are counted apart.
"""
from __future__ import annotations

import sys
import time

import numpy as np

from micro.common.files import atomic_path, atomic_write_text, manifest, write_json

from homogenize.experiments.causes import CAUSES, applicable
from homogenize.experiments.diagnose import diagnose
from homogenize.experiments.synthetic import generate, study_cases
from pathlib import Path
from micro.common.progress import progress_bar

__all__ = ["run_study", "summarize"]

LABELS = CAUSES + ("none",)


def run_study(n: int, seed: int = 0, progress: bool = True) -> list[dict]:
    """Diagnose ``n`` synthetic cases; one record per case."""
    records = []
    it = study_cases(n, seed)
    bar = None
    if progress:
        bar = progress_bar(total=len(it), desc="diagnose-study", unit="case", file=sys.stderr)
    for hidden, kind, s in it:
        t0 = time.perf_counter()
        case = generate(hidden, kind, seed=s)
        unavailable = sorted(c for c in case.expected
                             if applicable(c, case.experiment)[1].startswith("unavailable"))
        try:
            d = diagnose(case.experiment).as_dict()
        except Exception as exc:        # recorded and counted, never hidden: see summary
            print(f"diagnose-study: case seed {s} ({kind}, {hidden}) failed: {exc!r}",
                  file=sys.stderr)
            records.append({"seed": s, "kind": kind, "hidden": list(hidden),
                            "expected": sorted(case.expected), "error": repr(exc),
                            "unavailable": unavailable})
            if bar is not None:
                bar.update(1)
            continue
        found = d["causes"]
        records.append({"seed": s, "kind": kind, "hidden": list(hidden),
                        "expected": sorted(case.expected), "found": found,
                        "exact": set(found) == set(case.expected),
                        "false_causes": sorted(set(found) - set(case.expected)),
                        "missed": sorted(set(case.expected) - set(found)),
                        "gain": d["gain"], "baseline_cv_rmse": d["baseline"]["cv_rmse"],
                        "final_cv_rmse": d["final"]["cv_rmse"], "noise": case.noise,
                        "unavailable": unavailable, "seconds": time.perf_counter() - t0})
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return records


def summarize(records: list[dict]) -> dict:
    """Confusion matrix, false-cause rate, exact-recovery rate, median gain."""
    errors = [r for r in records if "error" in r]
    records = [r for r in records if "error" not in r]
    usable = [r for r in records if not r["unavailable"]]
    idx = {c: i for i, c in enumerate(LABELS)}
    conf = np.zeros((len(LABELS), len(LABELS)), dtype=int)
    for r in usable:
        for e in (r["expected"] or ["none"]):
            for f in (r["found"] or ["none"]):
                conf[idx[e], idx[f]] += 1
    with_cause = [r for r in usable if r["expected"]]
    per_cause = {}
    for c in CAUSES:
        rs = [r for r in usable if c in r["expected"]]
        if rs:
            per_cause[c] = {"cases": len(rs), "recovered": sum(c in r["found"] for r in rs)}
    outcomes = {}
    for c in CAUSES:
        hid = [c in r["expected"] for r in usable]
        nam = [c in r["found"] for r in usable]
        o = {"hidden_and_named": sum(h and n for h, n in zip(hid, nam)),
             "hidden_not_named": sum(h and not n for h, n in zip(hid, nam)),
             "named_not_hidden": sum(n and not h for h, n in zip(hid, nam))}
        if any(o.values()):
            outcomes[c] = o
    gains = [r["gain"] for r in with_cause]
    return {
        "n_cases": len(records) + len(errors),
        "n_errors": len(errors),
        "n_unavailable": len(records) - len(usable),
        "unavailable_causes": sorted({c for r in records for c in r["unavailable"]}),
        "n_used": len(usable),
        "exact_recovery_rate": float(np.mean([r["exact"] for r in usable])) if usable else None,
        "false_cause_rate": float(np.mean([bool(r["false_causes"]) for r in usable])) if usable else None,
        "null_false_cause_rate": (float(np.mean([bool(r["found"]) for r in usable if not r["expected"]]))
                                  if any(not r["expected"] for r in usable) else None),
        "median_gain": float(np.median(gains)) if gains else None,
        "per_cause_recovery": per_cause,
        "per_cause_outcomes": outcomes,
        "confusion_labels": list(LABELS),
        "confusion": conf.tolist(),
    }


def write_study(records, summary, out_dir, config) -> None:
    """study.json, confusion.csv, confusion.png and manifest.json in ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "study.json", {"summary": summary, "cases": records})
    conf = np.array(summary["confusion"])
    lab = summary["confusion_labels"]
    lines = ["expected \\ named," + ",".join(lab)]
    lines += [lab[i] + "," + ",".join(str(v) for v in conf[i]) for i in range(len(lab))]
    atomic_write_text(out / "confusion.csv", "\n".join(lines) + "\n")
    oc = summary["per_cause_outcomes"]
    rows = ["cause,hidden_and_named,hidden_not_named,named_not_hidden"]
    rows += [f"{c},{o['hidden_and_named']},{o['hidden_not_named']},{o['named_not_hidden']}"
             for c, o in oc.items()]
    atomic_write_text(out / "per_cause.csv", "\n".join(rows) + "\n")
    _plot_confusion(oc, summary, out / "confusion.png")
    write_json(out / "manifest.json", manifest(config, config.get("seed")))


def _plot_confusion(outcomes, summary, path):
    """Per cause, each case counted once: hidden and named, hidden but missed, named though not
    hidden (a false cause). A case with several hidden causes appears once in each of their
    rows, never off a diagonal as in a cause-by-cause matrix."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    causes = list(outcomes)
    cols = ("hidden_and_named", "hidden_not_named", "named_not_hidden")
    heads = ("hidden and named\n(recovered)", "hidden, not named\n(missed)",
             "named, not hidden\n(false cause)")
    M = np.array([[outcomes[c][k] for k in cols] for c in causes], dtype=int).reshape(-1, 3)
    fig = Figure(figsize=(7.5, 0.42 * max(len(causes), 1) + 2.2))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    if not causes:              # no case had or named a cause: an empty table, said so
        M = np.zeros((1, 3), dtype=int)
        causes = ["(no cause hidden or named)"]
    colours = np.zeros(M.shape + (3,)) + 1.0
    tint = np.array([[0.75, 0.9, 0.75], [1.0, 0.85, 0.6], [1.0, 0.7, 0.7]])
    for j in range(3):
        w = M[:, j] / max(M[:, j].max(), 1)      # each column on its own scale
        colours[:, j, :] = 1.0 - w[:, None] * (1.0 - tint[j])
    ax.imshow(colours, aspect="auto")
    ax.set_xticks(range(3), heads, fontsize=8)
    ax.set_yticks(range(len(causes)), causes, fontsize=8)
    for i in range(len(causes)):
        for j in range(3):
            ax.text(j, i, str(M[i, j]), ha="center", va="center", fontsize=8)
    ax.set_xlabel("number of synthetic cases (each case counted once per cause)")
    fr = summary["false_cause_rate"]
    g = summary["median_gain"]
    ax.set_title(f"{summary['n_used']} synthetic cases: exact recovery "
                 f"{summary['exact_recovery_rate']:.1%}\ncases with a false cause {fr:.1%}, "
                 f"median gain {g:.3g}" if fr is not None and g is not None
                 else "diagnose-study", fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
