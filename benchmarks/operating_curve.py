"""Success against objects cleared as VGN's quality threshold moves: one curve per model and request.

    python -m benchmarks.operating_curve [--results docs/results] [--scenario pile-5] [--out docs/operating-curve.png]

A higher threshold leaves fewer grasps to choose from: those tried succeed more often, and a
round ends sooner for want of a grasp, so fewer objects are cleared. A success rate alone can
therefore be bought with the threshold; two models (or two requests) compare only along the whole
curve, or at the same share of objects cleared. The points are the clutter benchmark's result
folders (``table.json``, ``python -m benchmarks.clutter --threshold T --out FOLDER``): every
(model, request, scenario and sensing) measured at two or more thresholds, random selection, the
newest run at each threshold; folders of changed code (``variant.md``) are left out.
``python -m benchmarks.report`` tables the curves (docs/generated/operating-curves.md, from
``report.operating_curves``); this command draws one scenario's curves, with 95 % intervals on
both axes and the dates and machines they were measured on in the title.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from benchmarks import report


def draw(curves: dict[report.CurveKey, list[report.CurvePoint]], scenario: str, out: Path) -> Path:
    """One scenario's curves as a PNG: objects cleared (x) against success (y), each point
    labelled with its threshold."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    chosen = {key: points for key, points in curves.items() if key[2] == scenario}
    if not chosen:
        raise ValueError(f"no curve of {scenario!r} (curves: {sorted({key[2] for key in curves})})")
    figure, axes = plt.subplots(figsize=(7.0, 5.0))
    measured_on: set[str] = set()
    for (model, request, _), points in chosen.items():
        cleared = [p.row["percent_cleared"] for p in points]
        success = [p.row["success_rate"] for p in points]
        xerr = _errors(points, "percent_cleared")
        yerr = _errors(points, "success_rate")
        axes.errorbar(
            cleared, success, xerr=xerr, yerr=yerr, marker="o", capsize=3, label=f"{model}, {request}"
        )
        for point, x, y in zip(points, cleared, success, strict=True):
            axes.annotate(
                f"{point.threshold:g}", (x, y), textcoords="offset points", xytext=(5, 5), fontsize=8
            )
            measured_on.add(report.machine_text(report.row_measured(point.row, point.folder)))
    axes.set_xlabel("objects cleared %")
    axes.set_ylabel("grasp success %")
    axes.set_title(
        f"{scenario}: success against objects cleared by quality threshold\n"
        f"measured {'; '.join(sorted(measured_on))}",
        fontsize=9,
    )
    axes.grid(alpha=0.3)
    axes.legend(fontsize=8)
    figure.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=120)
    plt.close(figure)
    return out


def _errors(points: list[report.CurvePoint], key: str) -> list[list[float]]:
    """Matplotlib's (2, N) error lengths from each row's 95 % interval (0 where none)."""
    low, high = [], []
    for point in points:
        value, interval = point.row[key], point.row.get(f"{key}_ci95") or [point.row[key]] * 2
        low.append(value - interval[0])
        high.append(interval[1] - value)
    return [low, high]


def main(argv: list[str] | None = None) -> int:
    """Draw one scenario's curves; the exit status for the shell."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--results", type=Path, default=report.ROOT / "docs" / "results")
    parser.add_argument("--scenario", default="pile-5", help="scenario with how it was seen, as tabled")
    parser.add_argument("--out", type=Path, default=report.ROOT / "docs" / "operating-curve.png")
    args = parser.parse_args(argv)
    try:
        print(f"wrote {draw(report.operating_curves(args.results), args.scenario, args.out)}")
    except ValueError as error:
        parser.error(str(error))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
