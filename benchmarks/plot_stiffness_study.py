"""The stiffness study's figure (docs/studies.md, "Where stiffness pays"): per task, each
world (rows) against each stiffness policy (columns) from a stiffness sweep's trials.

A cell is green when the reproduction did the task with every force on the environment
within the task's bound (``reproduction.success`` and ``reproduction.safe``; the fraction of
seeds if several), orange when it kept the bound but failed the task, red when a force
passed the bound; its text is the peak force on the environment (N, mean over seeds) and,
in the push worlds, the time to return within 5 mm of the demonstrated path after the
release (s; "-" never). Cells not run yet are grey.

    python benchmarks/plot_stiffness_study.py runs/study_stiffness_pin runs/study_stiffness_drawing \
        -o docs/img/study_stiffness.png
"""

import argparse
import json
from pathlib import Path

import numpy as np

SUCCESS = "reproduction.success"
SAFE = "reproduction.safe"
FORCE = "reproduction.interaction.environment_force_peak_n"
RETURN = "reproduction.push.return_time_s"


def _rows(folder):
    """The finished trials of a sweep folder (its ``trials/*/trial.json``: a sweep still
    running, or stopped, has no results.csv yet), as flat rows."""
    rows = []
    for path in sorted(Path(folder).glob("trials/*/trial.json")):
        record = json.loads(path.read_text(encoding="utf-8"))
        if record["status"] == "done":
            rows.append({**record["labels"], "seed": str(record["seed"]),
                         **{k: str(v) for k, v in record["metrics"].items()}})  # fmt: skip
    return rows


def _number(text):
    return None if text in ("", "None", None) else float(text)


def table(rows):
    """{(world, policy): dict(good, unsafe, force, back, n)} over the seeds."""
    cells = {}
    for row in rows:
        key = (row["world"], row["policy"])
        cell = cells.setdefault(key, dict(good=[], unsafe=[], force=[], back=[], n=0))
        done, safe = row[SUCCESS] == "True", row[SAFE] == "True"
        cell["good"].append(done and safe)
        cell["unsafe"].append(not safe)
        cell["force"].append(_number(row[FORCE]))
        cell["back"].append(_number(row.get(RETURN)))
        cell["n"] += 1
    return cells


def _planned(folder):
    """The worlds and policies the sweep file in ``folder`` names, in its order."""
    from hemg_drake.sweep.spec import parse_sweep

    spec = parse_sweep((Path(folder) / "sweep.yaml").read_text(encoding="utf-8"))
    axes = {axis.name: list(axis.cases) for axis in spec.axes}
    return axes["world"], axes["policy"]


def draw(axis, rows, title, worlds, policies):
    import matplotlib.colors as mcolors

    cells = table(rows)
    image = np.full((len(worlds), len(policies)), np.nan)
    for (world, policy), cell in cells.items():
        i, j = worlds.index(world), policies.index(policy)
        image[i, j] = 2.0 if np.mean(cell["good"]) == 1 else (0.0 if any(cell["unsafe"]) else 1.0)
        force = np.mean([f for f in cell["force"] if f is not None])
        text = f"{force:.0f} N"
        if world.startswith("push"):
            backs = cell["back"]
            text += "\n" + ("-" if any(b is None for b in backs) else f"{np.mean(backs):.2f} s")
        axis.text(j, i, text, ha="center", va="center", fontsize=7)
    colours = mcolors.ListedColormap(["#e07b7b", "#f3c27a", "#8fd18f"])
    colours.set_bad("#dddddd")
    axis.imshow(np.ma.masked_invalid(image), cmap=colours, vmin=0, vmax=2, aspect="auto")
    axis.set_xticks(range(len(policies)), policies, rotation=30, ha="right", fontsize=8)
    axis.set_yticks(range(len(worlds)), worlds, fontsize=8)
    axis.set_title(title, fontsize=9)


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folders", nargs="+", help="sweep output folders (--out of the sweep)")
    parser.add_argument("-o", "--output", default="study_stiffness.png")
    args = parser.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, len(args.folders), figsize=(5.6 * len(args.folders), 5.4))
    for axis, folder in zip(np.atleast_1d(axes), args.folders, strict=True):
        rows = _rows(folder)
        task = Path(folder).name
        seeds = sorted({row["seed"] for row in rows})
        worlds, policies = _planned(folder)
        done = len(rows)
        draw(axis, rows, f"{task}: seeds {', '.join(seeds)} ({done} of "
             f"{len(worlds) * len(policies) * len(seeds)} trials)", worlds, policies)  # fmt: skip
    figure.suptitle("green: task done, forces within bound; orange: within bound, task failed;\n"
                    "red: bound passed; grey: not run. Text: peak force on the environment (N); "
                    "push worlds: return within 5 mm after the release (s)", fontsize=8)  # fmt: skip
    figure.tight_layout()
    figure.savefig(args.output, dpi=110)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
