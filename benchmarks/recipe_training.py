"""What training from scene recipes costs beside training from stored grids.

    python -m benchmarks.recipe_training --data data --grids GRID_SHARDS --out docs/results/recipe-training

Two figures, measured in one run:

- **Rendering**: observations per second that ``vgn-data render`` makes from recipes (rebuild the
  scene, render 1-6 views, add sensor noise, fuse), with ``--workers`` processes, into a fresh
  cache (a temporary folder).
- **An epoch**: ``vgn-train`` for one epoch over the same number of scenes, from stored grids (a
  folder of grid shards, e.g. ``vgn-data legacy-grids data --out DIR``) and from recipes with
  ``--observations K`` (one of K cached observations drawn at every draw of a scene), run
  alternately ``--repeats`` times so that a machine's drift hits both alike.

Writes ``recipe-training.json`` (and ``measured.json``: date and machine) to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from statistics import median

from benchmarks.report import this_machine
from training.observations import ObservationSettings, render_cache
from training.recipe_shards import RecipeFolder


def render_rate(data: Path, per_scene: int, workers: int) -> dict:
    """Render every scene's observations into a new cache; scenes and observations per second."""
    settings = ObservationSettings(per_scene=per_scene)
    scenes = sum(entry["scenes"] for entry in RecipeFolder(data).manifest()["shards"])
    with tempfile.TemporaryDirectory() as cache:
        started = time.perf_counter()
        render_cache(data, Path(cache), settings, workers)
        seconds = time.perf_counter() - started
    return {"scenes": scenes, "per_scene": per_scene, "workers": workers, "seconds": round(seconds, 1),
            "scenes_per_s": round(scenes / seconds, 2), "observations_per_s": round(scenes * per_scene / seconds, 2)}  # fmt: skip


def epoch_seconds(data: list[str], scenes: int, out: Path, extra: list[str]) -> float:
    """Seconds of one training epoch over ``scenes`` scenes (from the run's model card)."""
    weights = out / "vgn.safetensors"
    command = [sys.executable, "-m", "training.cli", *(a for d in data for a in ("--data", d)), "--train-scenes",
               str(scenes), "--epochs", "1", "--val-fraction", "0", "--threads", "1", "--threshold", "0.9",
               "--no-progress", "--fresh", "--out", str(weights), *extra]  # fmt: skip
    subprocess.run(command, check=True, capture_output=True, text=True)
    card = json.loads(weights.with_suffix(".card.json").read_text())
    return float(card["history"][-1]["seconds"])


def main(argv: list[str] | None = None) -> int:
    """Measure, print and write the figures."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--data", type=Path, default=Path("data"), help="recipe folder")
    parser.add_argument("--grids", type=Path, required=True, help="grid-shard folder to compare with")
    parser.add_argument("--cache", type=Path, required=True, help="observation cache for the recipe epochs")
    parser.add_argument("--scenes", type=int, default=300, help="training scenes per epoch")
    parser.add_argument("--observations", type=int, default=4, help="cached observations per scene")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--workers", type=int, default=2, help="render processes")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    rendering = render_rate(args.data, args.observations, args.workers)
    print(f"rendering: {rendering['scenes_per_s']} scenes/s, {rendering['observations_per_s']} observations/s "
          f"({args.workers} workers)")  # fmt: skip
    recipe_extra = ["--cache", str(args.cache), "--observations", str(args.observations)]
    times: dict[str, list[float]] = {"grids": [], "recipes": []}
    with tempfile.TemporaryDirectory() as work:
        for _ in range(args.repeats):
            times["grids"].append(epoch_seconds([str(args.grids)], args.scenes, Path(work) / "g", []))
            times["recipes"].append(
                epoch_seconds([str(args.data)], args.scenes, Path(work) / "r", recipe_extra)
            )
    ratio = median(times["recipes"]) / median(times["grids"])
    print(f"epoch over {args.scenes} scenes: grids {times['grids']} s, recipes {times['recipes']} s, "
          f"ratio {ratio:.2f} (target <= 1.5)")  # fmt: skip
    result = {"rendering": rendering, "epoch": {"scenes": args.scenes, "observations": args.observations,
              "seconds": times, "ratio": round(ratio, 3), "target": 1.5}}  # fmt: skip
    (args.out / "recipe-training.json").write_text(json.dumps(result, indent=2) + "\n")
    (args.out / "measured.json").write_text(json.dumps(this_machine(), indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
