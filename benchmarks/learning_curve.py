r"""Executed-grasp success against the number of training scenes: how much data the model needs.

    python -m benchmarks.learning_curve --sizes 1000 2000 4000 --scenario pile-5 --rounds 100 \
        --objects ~/vgn-data/objects/pile/heldout --out ~/vgn-data/curve \
        -- --data data --epochs 20 --copies 4 --patience 4

Everything after ``--`` is a ``vgn-train`` command line without ``--out``: each size trains the
same way on a nested subset of the training scenes (``--train-scenes``; validation unchanged),
into ``OUT/scenes-N/``. Each model then runs the clutter-removal benchmark on held-out objects
with the same seed. Training and benchmark runs resume, so the command can be repeated after an
interruption, or split by ``--phase``: ``train`` on a machine with a GPU, ``bench`` where the
simulator is installed, ``report`` to tabulate. The report fits success = a + b·log10(scenes)
by weighted least squares and states the size the fit reaches the paper's VGN success at; that
extrapolation is only as good as the straight line on a log axis, and the report says so.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

from vgn_data.files import write_atomically

PHASES = ("train", "bench", "report")


@dataclass(frozen=True)
class CurvePoint:
    """One dataset size: what the model trained on and how it grasped."""

    requested_scenes: int
    train_scenes: int
    steps: int
    best_epoch: int
    val_balanced_loss: float | None
    rounds: int
    success_rate: float | None
    success_rate_ci95: tuple[float, float]
    percent_cleared: float | None
    percent_cleared_ci95: tuple[float, float]
    outcomes: dict[str, int]


@dataclass(frozen=True)
class LogFit:
    """success % = intercept + slope · log10(scenes), and where it reaches ``target``.

    ``scenes_for_target`` is None unless the slope's 95 % interval (from the points' own
    intervals) lies above zero: a flat curve predicts no size, however small its slope.
    """

    intercept: float
    slope: float
    slope_ci95: tuple[float, float]
    target: float
    scenes_for_target: float | None


def parse_args(argv: list[str]) -> tuple[argparse.Namespace, list[str]]:
    """This tool's options, and the ``vgn-train`` options after ``--``."""
    own, train_argv = (argv[: argv.index("--")], argv[argv.index("--") + 1 :]) if "--" in argv else (argv, [])
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--sizes", type=int, nargs="+", required=True, help="training-scene counts, e.g. 1000 2000 4000"
    )
    parser.add_argument(
        "--scenario", default="pile-5", help="SCENE-COUNT of the benchmark (default %(default)s)"
    )
    parser.add_argument("--objects", type=Path, help="held-out objects for the scenario's scene type")
    parser.add_argument(
        "--rounds", type=int, default=100, help="benchmark rounds per size (default %(default)s)"
    )
    parser.add_argument("--seed", type=int, default=1, help="benchmark seed, the same for every size")
    parser.add_argument(
        "--threshold", type=float, help="VGN threshold (default: each model's operating threshold)"
    )
    parser.add_argument(
        "--target", type=float, help="success %% to extrapolate to (default: the paper's VGN row)"
    )
    parser.add_argument("--phase", choices=[*PHASES, "all"], default="all")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(own)
    if any(size < 1 for size in args.sizes):
        parser.error("--sizes must be positive scene counts")
    if args.phase in ("train", "all") and not train_argv:
        parser.error("give the vgn-train options after --, e.g. -- --data data --epochs 20")
    if any(arg == "--out" or arg.startswith("--out=") or arg == "--train-scenes" for arg in train_argv):
        parser.error(
            "the vgn-train options must not hold --out or --train-scenes: this tool sets them per size"
        )
    args.sizes = sorted(set(args.sizes))
    return args, train_argv


def weights_path(out: Path, size: int) -> Path:
    """Where the model trained on ``size`` scenes is written (its checkpoint and card beside it)."""
    return out / f"scenes-{size}" / "vgn.safetensors"


def bench_folder(out: Path, size: int) -> Path:
    """The clutter-benchmark results of the ``size``-scene model: a resumable folder."""
    return out / f"scenes-{size}" / "bench"


def train_size(out: Path, size: int, train_argv: list[str]) -> None:
    """Train (or continue training) the model of one size; a finished run only rewrites its card."""
    from training.checkpoint import checkpoint_path
    from training.cli import main as train_main

    weights = weights_path(out, size)
    weights.parent.mkdir(parents=True, exist_ok=True)
    resume = ["--resume"] if checkpoint_path(weights).exists() else []
    argv = [*train_argv, "--train-scenes", str(size), "--out", str(weights), *resume]
    if train_main(argv) != 0:
        raise SystemExit(f"learning curve: training for {size} scenes failed (vgn-train {' '.join(argv)})")


def bench_size(args: argparse.Namespace, size: int) -> None:
    """Run (or extend) the clutter benchmark of one size's model."""
    from benchmarks.clutter import main as clutter_main

    weights = weights_path(args.out, size)
    if not weights.is_file():
        raise SystemExit(
            f"learning curve: no weights for {size} scenes at {weights}; run --phase train first"
        )
    scene = args.scenario.split("-")[0]
    argv = ["--model", str(weights), "--rounds", str(args.rounds), "--seed", str(args.seed)]
    # Plain requests: the curve measures the network alone, as its points always have.
    argv += ["--planners", "vgn", "--selections", "random", "--scenarios", args.scenario, "--no-turn-average"]
    argv += ["--out", str(bench_folder(args.out, size))]
    if args.objects and scene in ("pile", "packed"):
        argv += [f"--{scene}-objects", str(args.objects)]
    if args.threshold is not None:
        argv += ["--threshold", str(args.threshold)]
    if clutter_main(argv) != 0:
        raise SystemExit(f"learning curve: the benchmark for {size} scenes failed")


def read_point(out: Path, size: int) -> CurvePoint | None:
    """The size's training card and benchmark table, or None while either is missing."""
    card_file = weights_path(out, size).with_suffix(".card.json")
    table_file = bench_folder(out, size) / "table.json"
    if not card_file.is_file() or not table_file.is_file():
        return None
    card, rows = json.loads(card_file.read_text()), json.loads(table_file.read_text())
    if not rows:
        return None
    row, training = rows[0], card.get("training", {})
    history = card.get("history") or []
    best = min(
        history,
        key=lambda entry: (entry.get("val") or {}).get("balanced_loss") or math.inf,
        default={},
    )
    return CurvePoint(
        requested_scenes=size,
        train_scenes=int(training.get("train_scenes", 0)),
        steps=int(history[-1].get("steps", 0)) if history else 0,
        best_epoch=int(best.get("epoch", 0)),
        val_balanced_loss=(best.get("val") or {}).get("balanced_loss"),
        rounds=int(row["rounds"]),
        success_rate=row["success_rate"],
        success_rate_ci95=tuple(row["success_rate_ci95"]),
        percent_cleared=row["percent_cleared"],
        percent_cleared_ci95=tuple(row["percent_cleared_ci95"]),
        outcomes=dict(row.get("outcomes") or {}),
    )


def fit_log_curve(points: list[CurvePoint], target: float) -> LogFit | None:
    """Weighted least squares on log10(scenes); each point weighs by 1/width² of its interval,
    so a short run counts less. None with fewer than two sizes or no successes measured."""
    import numpy as np

    usable = [p for p in points if p.success_rate is not None and p.train_scenes > 0]
    if len({p.train_scenes for p in usable}) < 2:
        return None
    x = np.log10([p.train_scenes for p in usable])
    y = np.array([p.success_rate for p in usable])
    half_widths = np.array([max((p.success_rate_ci95[1] - p.success_rate_ci95[0]) / 2, 1.0) for p in usable])
    sigmas = half_widths / 1.96  # a 95 % interval's half-width in standard deviations
    design = np.stack([np.ones_like(x), x], axis=1) / sigmas[:, None]
    (intercept, slope), *_ = np.linalg.lstsq(design, y / sigmas, rcond=None)
    slope_error = 1.96 * math.sqrt(np.linalg.inv(design.T @ design)[1, 1])
    slope_ci95 = (float(slope - slope_error), float(slope + slope_error))
    reach = 10 ** ((target - intercept) / slope) if slope_ci95[0] > 0 else None
    return LogFit(float(intercept), float(slope), slope_ci95, target, None if reach is None else float(reach))


def markdown(points: list[CurvePoint], fit: LogFit | None, args: argparse.Namespace) -> str:
    """The measured points and the fit as Markdown, with the fit's caveat spelled out."""
    lines = [
        f"{args.scenario}, held-out objects, random selection, seed {args.seed}",
        "",
        "| training scenes | optimizer steps | best epoch | val balanced loss | rounds | success % (95 % CI) "
        "| cleared % (95 % CI) | failures: approach contact / nothing held / slipped / collision |",
        "| ---: | ---: | ---: | ---: | ---: | --- | --- | --- |",
    ]
    for p in points:
        success = "-" if p.success_rate is None else f"{p.success_rate:.1f}"
        cleared = "-" if p.percent_cleared is None else f"{p.percent_cleared:.1f}"
        loss = "-" if p.val_balanced_loss is None else f"{p.val_balanced_loss:.4f}"
        failures = " / ".join(
            str(p.outcomes.get(k, 0)) for k in ("approach_contact", "nothing_held", "slipped", "collision")
        )
        lines.append(
            f"| {p.train_scenes} | {p.steps} | {p.best_epoch} | {loss} | {p.rounds} | "
            f"{success} ({p.success_rate_ci95[0]:.1f}-{p.success_rate_ci95[1]:.1f}) | "
            f"{cleared} ({p.percent_cleared_ci95[0]:.1f}-{p.percent_cleared_ci95[1]:.1f}) | {failures} |"
        )
    lines.append("")
    if fit is None:
        lines.append("No fit: it needs successes measured at two or more dataset sizes.")
    else:
        slope = f"{fit.slope:.1f} (95 % CI {fit.slope_ci95[0]:.1f} to {fit.slope_ci95[1]:.1f})"
        if fit.scenes_for_target is None:
            lines.append(
                f"Fit: success = {fit.intercept:.1f} + {slope}·log10(scenes): not rising beyond the "
                f"intervals, so no size is predicted to reach {fit.target:.1f} %."
            )
        else:
            lines.append(
                f"Fit: success = {fit.intercept:.1f} + {slope}·log10(scenes); it reaches "
                f"{fit.target:.1f} % at about {fit.scenes_for_target:.2g} training scenes. An extrapolation "
                "of a straight line on a log axis: treat it as an order of magnitude."
            )
    return "\n".join(lines) + "\n"


def write_plot(points: list[CurvePoint], fit: LogFit | None, path: Path) -> Path | None:
    """Success with intervals against training scenes (log axis), with the fit and the target."""
    measured = [p for p in points if p.success_rate is not None]
    if not measured:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    import numpy as np

    figure, axes = plt.subplots(figsize=(6, 4))
    x = [p.train_scenes for p in measured]
    y = [p.success_rate for p in measured]
    errors = [
        [p.success_rate - p.success_rate_ci95[0] for p in measured],
        [p.success_rate_ci95[1] - p.success_rate for p in measured],
    ]
    axes.errorbar(x, y, yerr=errors, fmt="o", capsize=4, label="measured (95 % CI)")
    if fit is not None:
        right = max(max(x) * 2, min(fit.scenes_for_target or 0, max(x) * 1000))
        line_x = np.geomspace(min(x) / 1.5, right * 1.2, 50)
        axes.plot(line_x, fit.intercept + fit.slope * np.log10(line_x), "--", label="fit a + b·log10(scenes)")
        axes.axhline(fit.target, color="gray", linewidth=0.8, label=f"target {fit.target:.1f} %")
    axes.set_xscale("log")
    axes.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())  # labels on decades only
    axes.set_xlabel("training scenes")
    axes.set_ylabel("executed-grasp success %")
    axes.set_ylim(0, 100)
    axes.grid(True, which="both", alpha=0.3)
    axes.legend(loc="lower right", fontsize=8)
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.name}.tmp.png")
    figure.savefig(temporary, dpi=120)
    plt.close(figure)
    temporary.replace(path)
    return path


def report(args: argparse.Namespace) -> int:
    """Tabulate, fit and plot whatever sizes are measured so
    far into ``--out``; sizes still missing are listed."""
    from benchmarks.clutter import PAPER_TABLE_1

    points = [p for p in (read_point(args.out, size) for size in args.sizes) if p is not None]
    missing = [size for size in args.sizes if size not in {p.requested_scenes for p in points}]
    target = args.target if args.target is not None else PAPER_TABLE_1.get(args.scenario, (50.0,))[0]
    fit = fit_log_curve(points, target)
    table = markdown(points, fit, args)
    if missing:
        table += f"\nNot measured yet: {', '.join(map(str, missing))} scenes.\n"
    write_atomically(args.out / "curve.md", table)
    payload = {"scenario": args.scenario, "seed": args.seed, "points": [asdict(p) for p in points]}
    payload["fit"] = None if fit is None else asdict(fit)
    write_atomically(args.out / "curve.json", json.dumps(payload, indent=2) + "\n")
    plot = write_plot(points, fit, args.out / "curve.png")
    print(table + (f"plot: {plot}\n" if plot else ""))
    return 0


def main(argv: list[str] | None = None) -> int:
    """Train and benchmark every size the phase asks for, then report."""
    args, train_argv = parse_args(sys.argv[1:] if argv is None else argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for size in args.sizes:
        if args.phase in ("train", "all"):
            train_size(args.out, size, train_argv)
        if args.phase in ("bench", "all"):
            bench_size(args, size)
    return report(args)


if __name__ == "__main__":
    sys.exit(main())
