"""Why the visual operator fails in the shared-control study (docs/studies.md, "Shared
control"): per delay and mode, from each trial's logs (``trials/*/run``: dataset.npz and
interaction.npz), the mean assist weight (over the run and while the operator works,
activation > 0.5), the largest correction the operator made, the plan-clock time where it
gave up, and per task: the pin, how often the tool fell back below 2 cm after having been
above 8 cm (the pin pushed back in: the correction oscillating); the drawing, the pen's
touches (contacts with the sheet, however short: 3 for a clean drawing) and the ink
pieces they make (``demonstration.strokes``).

    python benchmarks/diagnose_assist_study.py runs/study_assist_pin
"""

import argparse
import json
from pathlib import Path

import numpy as np

from hemg_drake.analysis.contact import contact_runs, in_contact
from hemg_drake.evaluation import stroke_runs
from hemg_drake.fileio import load_npz
from hemg_drake.learning.demos import load_dataset
from hemg_drake.teleop.visual import C, GAVE_UP


def swings(rise):
    """Times the tool fell below 2 cm after having been above 8 cm (a pin pushed back)."""
    count, high = 0, False
    for z in rise:
        if z >= 0.08:
            high = True
        elif z < 0.02 and high:
            count, high = count + 1, False
    return count


def diagnose(folder):
    cells = {}
    for path in sorted(Path(folder).glob("trials/*/trial.json")):
        record = json.loads(path.read_text(encoding="utf-8"))
        run = path.parent / "run"
        if record["status"] != "done" or not (run / "interaction.npz").is_file():
            continue
        demo = load_dataset(run / "dataset.npz")[0][0]
        logs = load_npz(run / "interaction.npz", kind="interaction log")
        time = logs["demo0.time"][:, 0]
        visual = logs["demo0.visual_state"]
        gave = np.flatnonzero(visual[:, GAVE_UP] > 0)
        if "demonstration.strokes" in record["metrics"]:  # the drawing
            row = {
                "touches": len(contact_runs(in_contact(demo.f_WE), 1)),
                "pieces": len(stroke_runs(demo.time, demo.f_WE)[0]),
            }
        else:
            row = {"swings": swings(demo.p_WE[:, 2] - demo.p_WE[0, 2])}
        row |= {
            "correction_mm": 1e3 * np.linalg.norm(visual[:, C], axis=1).max(),
            "held_at_s": visual[gave[0], 0] if len(gave) else np.nan,
        }
        if "demo0.assist.weight" in logs:
            weight = logs["demo0.assist.weight"][:, 0]
            n = min(len(weight), len(demo.activation))
            working = demo.activation[:n] > 0.5
            row["w_mean"] = weight.mean()
            row["w_working"] = weight[:n][working].mean() if working.any() else np.nan
        labels = record["labels"]
        key = (labels.get("operator", ""), int(labels["delay_ms"]), labels["mode"])
        cells.setdefault(key, []).append(row)
    return cells


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+")
    args = parser.parse_args()
    cells = {}
    for folder in args.folders:
        for key, rows in diagnose(folder).items():
            cells.setdefault(key, []).extend(rows)
    present = {name for rows in cells.values() for row in rows for name in row}
    names = [name for name in ("swings", "touches", "pieces") if name in present]
    names += ["correction_mm", "held_at_s", "w_mean", "w_working"]
    order = {"none": 0, "fixed": 1, "confidence": 2, "emg": 3}
    ranks = {"nominal": 0, "noisy": 1, "slow": 2}  # the order
    for operator in sorted({key[0] for key in cells}, key=lambda o: (ranks.get(o, 3), o)):
        if operator:
            print(f"\n{operator}:\n")
        print("| delay (ms) | mode | n | " + " | ".join(names) + " |")
        print("|---" * (3 + len(names)) + "|")
        mine = [(key[1:], rows) for key, rows in cells.items() if key[0] == operator]
        for (delay, mode), rows in sorted(mine, key=lambda kv: (kv[0][0], order[kv[0][1]])):
            values = []
            for name in names:
                found = [r[name] for r in rows if name in r and np.isfinite(r[name])]
                values.append(f"{np.mean(found):.3g}" if found else "-")
            print(f"| {delay} | {mode} | {len(rows)} | " + " | ".join(values) + " |")


if __name__ == "__main__":
    main()
