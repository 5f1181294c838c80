"""The clutter-removal table as a bar chart: success and percent cleared per scenario, each
measured run with its 95 % interval, beside the paper's VGN and GPD rows."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

PAPER_STYLE = {"hatch": "//", "edgecolor": "black", "linewidth": 0.6}


@dataclass(frozen=True)
class Series:
    """One group of bars: a label and, per scenario, (value, low, high) or None where absent."""

    label: str
    success: list[tuple[float, float, float] | None]
    cleared: list[tuple[float, float, float] | None]
    from_paper: bool = False


def chart_series(
    rows: list[dict], paper: dict[str, tuple[float, float]], gpd: dict[str, tuple[float, float]]
) -> tuple[list[str], list[Series]]:
    """Scenarios in table order and the bars to draw: measured (planner, selection) runs first,
    then the paper's VGN and GPD where it reports the scenario."""
    scenarios = list(dict.fromkeys(row["scenario"] for row in rows))
    runs = list(dict.fromkeys((row["planner"], row["selection"]) for row in rows))
    series = []
    for planner, selection in runs:
        by_scenario = {
            r["scenario"]: r for r in rows if (r["planner"], r["selection"]) == (planner, selection)
        }

        def measured(
            key: str, by_scenario: dict[str, dict] = by_scenario
        ) -> list[tuple[float, float, float] | None]:
            out = []
            for scenario in scenarios:
                row = by_scenario.get(scenario)
                value = row and row[key]
                out.append((value, *row[f"{key}_ci95"]) if value is not None else None)
            return out

        series.append(
            Series(f"{planner} ({selection})", measured("success_rate"), measured("percent_cleared"))
        )
    for label, table in (("paper VGN ε=0.9", paper), ("paper GPD", gpd)):
        if any(s in table for s in scenarios):
            success = [(table[s][0],) * 3 if s in table else None for s in scenarios]
            cleared = [(table[s][1],) * 3 if s in table else None for s in scenarios]
            series.append(Series(label, success, cleared, from_paper=True))
    return scenarios, series


def write_chart(
    rows: list[dict], paper: dict[str, tuple[float, float]], gpd: dict[str, tuple[float, float]], path: Path
) -> Path | None:
    """Save the chart as PNG; None when there is nothing to draw."""
    if not rows:
        return None
    import matplotlib

    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt

    scenarios, series = chart_series(rows, paper, gpd)
    figure, axes = plt.subplots(1, 2, figsize=(max(8.0, 2.6 * len(scenarios) + 3), 4.2), sharey=True)
    width = 0.8 / len(series)
    colours = plt.get_cmap("tab10").colors
    for axis, metric, title in (
        (axes[0], "success", "success rate %"),
        (axes[1], "cleared", "percent cleared %"),
    ):
        for index, bars in enumerate(series):
            values = getattr(bars, metric)
            xs = [i + (index - (len(series) - 1) / 2) * width for i, v in enumerate(values) if v]
            heights = [v[0] for v in values if v]
            errors = [[v[0] - v[1] for v in values if v], [v[2] - v[0] for v in values if v]]
            style = PAPER_STYLE if bars.from_paper else {}
            colour = "white" if bars.from_paper else colours[index % len(colours)]
            if bars.from_paper and "GPD" in bars.label:
                style = {**style, "hatch": ".."}
            axis.bar(
                xs, heights, width, label=bars.label, color=colour,
                yerr=None if bars.from_paper else errors, capsize=2, **style,
            )  # fmt: skip
        axis.set_xticks(range(len(scenarios)), scenarios)
        axis.set_title(title)
        axis.set_ylim(0, 105)
        axis.grid(axis="y", alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="lower center", ncol=min(len(series), 6), fontsize=8, frameon=False)
    figure.suptitle(
        "clutter removal (bars: measured, with 95 % intervals; hatched: the paper's Table 1)", fontsize=10
    )
    figure.tight_layout(rect=(0, 0.07, 1, 1))
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path
