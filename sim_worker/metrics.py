"""The paper's clutter-removal metrics over finished rounds, with 95 % confidence intervals."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from statistics import mean, median
from typing import Any

from sim_worker.results import ROUND_ENDINGS

Z_95 = 1.959964
#: Failure classes shown in summaries, as (outcome value, short label); "collision" joins the
#: pre-grasp and (labelling-only) approach collisions.
FAILURE_CLASSES = (
    ("approach_contact", "approach contact"),
    ("nothing_held", "nothing held"),
    ("slipped", "slipped"),
    ("collision", "collision"),
)


def outcome_counts(grasps: Iterable[Mapping[str, Any]]) -> dict[str, int]:
    """Attempts per outcome: success and each failure class (older results without the newer
    outcomes simply count zero there)."""
    counts = {"success": 0, **{key: 0 for key, _ in FAILURE_CLASSES}}
    for row in grasps:
        outcome = row.get("outcome") or ""
        key = "collision" if outcome.endswith("collision") else outcome
        if key in counts:
            counts[key] += 1
    return counts


def round_endings(rounds: Iterable[Mapping[str, Any]]) -> dict[str, int] | None:
    """Rounds per ending (``ROUND_ENDINGS``) and, for the rounds whose last look offered nothing,
    the last stage of the chain that dropped something: ``threshold`` (no candidate reached the
    checks), ``workspace`` (every one's open fingers reached outside the cube), ``clearance`` (the
    approach hit the surface for the rest) or ``grip`` (the grip check dropped the rest). Results
    from before the workspace was counted apart count it as clearance. None for results from before
    endings were recorded."""
    rounds = [row for row in rounds if row.get("ended")]
    if not rounds:
        return None
    stages = ("threshold", "workspace", "clearance", "grip")
    counts = {ending: 0 for ending in ROUND_ENDINGS} | dict.fromkeys(stages, 0)
    for row in rounds:
        counts[row["ended"]] += 1
        if row["ended"] != "no_grasp":
            continue
        candidates = int(row.get("last_candidates") or 0)
        by_workspace = int(row.get("last_workspace_dropped") or 0)
        by_clearance = int(row.get("last_clearance_dropped") or 0)
        if candidates == 0:
            counts["threshold"] += 1
        elif by_workspace == candidates:
            counts["workspace"] += 1
        else:
            counts["clearance" if by_workspace + by_clearance == candidates else "grip"] += 1
    return counts


def wilson_interval(successes: int, trials: int) -> tuple[float, float]:
    """95 % Wilson score interval of a proportion, in percent (robust when all or none succeed)."""
    if trials == 0:
        return (0.0, 0.0)
    p = successes / trials
    centre = (p + Z_95**2 / (2 * trials)) / (1 + Z_95**2 / trials)
    half = Z_95 * math.sqrt(p * (1 - p) / trials + Z_95**2 / (4 * trials**2)) / (1 + Z_95**2 / trials)
    return (round(100 * max(0.0, centre - half), 1), round(100 * min(1.0, centre + half), 1))


def _floats(rows: Iterable[Mapping[str, Any]], key: str) -> list[float]:
    return [float(row[key]) for row in rows if row.get(key) not in (None, "")]


def summarize(rounds: list[Mapping[str, Any]], grasps: list[Mapping[str, Any]]) -> dict[str, Any]:
    """Success rate = successes / attempts; percent cleared = objects removed by grasps /
    objects placed; planning time as the service reports it and as the client saw it."""
    attempts = sum(int(r["attempts"]) for r in rounds)
    successes = sum(int(r["successes"]) for r in rounds)
    placed = sum(int(r["object_count"]) for r in rounds)
    cleared = sum(int(r["cleared"]) for r in rounds)
    planning, client_planning = _floats(grasps, "planning_time"), _floats(grasps, "client_planning_time")
    integration = _floats(grasps, "integration_time")
    round_seconds = _floats(rounds, "seconds")
    attempted = [row for row in grasps if row.get("outcome") != "interrupted"]
    endings = round_endings(rounds)
    disturbed = [row for row in attempted if row.get("disturbance")]

    def stats(values: list[float]) -> dict[str, float] | None:
        return {"mean": round(mean(values), 2), "p50": round(median(values), 2)} if values else None

    return {
        "rounds": len(rounds),
        "attempts": attempts,
        "successes": successes,
        "success_rate": round(100 * successes / attempts, 1) if attempts else None,
        "success_rate_ci95": wilson_interval(successes, attempts),
        "objects_placed": placed,
        "objects_cleared": cleared,
        "percent_cleared": round(100 * cleared / placed, 1) if placed else None,
        "percent_cleared_ci95": wilson_interval(cleared, placed),
        "outcomes": outcome_counts(grasps),
        "endings": endings,
        "no_grasp_rate": round(100 * endings["no_grasp"] / sum(endings[e] for e in ROUND_ENDINGS), 1)
        if endings
        else None,
        "planning_ms": stats(planning),
        "client_planning_ms": stats(client_planning),
        "integration_ms": stats(integration),
        "round_seconds": stats(round_seconds),
        # Closing the loop: frames fused and time from the first frame to the plan of each look
        # before a grasp; the disturbed attempts; the closed loop's withdrawn approaches.
        "frames_per_plan": stats(_floats(grasps, "frames")),
        "first_grasp_ms": stats(_floats(grasps, "first_grasp_ms")),
        "disturbed_attempts": len(disturbed),
        "disturbed_successes": sum(int(row["label"]) for row in disturbed),
        "withdrawn": sum(row.get("outcome") == "interrupted" for row in grasps),
    }


def failure_breakdown(summary: Mapping[str, Any]) -> str:
    """``approach contact 3, nothing held 1, slipped 0, collision 0``."""
    outcomes = summary.get("outcomes") or {}
    return ", ".join(f"{label} {outcomes.get(key, 0)}" for key, label in FAILURE_CLASSES)


def endings_breakdown(summary: Mapping[str, Any]) -> str:
    """``cleared 3, two failures 5, no grasp offered 2 (threshold 1, workspace 0, clearance 0, grip 1)``."""
    endings = summary.get("endings")
    if not endings:
        return "-"
    text = f"cleared {endings['cleared']}, two failures {endings['failures']}, no grasp offered {endings['no_grasp']}"
    stages = ", ".join(
        f"{stage} {endings.get(stage, 0)}" for stage in ("threshold", "workspace", "clearance", "grip")
    )
    text += f" ({stages})"
    return text + (f", withdrawn {endings['withdrawn']}" if endings["withdrawn"] else "")


def summary_table(summary: Mapping[str, Any]) -> str:
    """A short human-readable table of a summary."""

    def ms(key: str) -> str:
        value = summary.get(key)
        return f"{value['mean']:.1f} ms (p50 {value['p50']:.1f})" if value else "-"

    def pct(key: str) -> str:
        value = summary.get(key)
        low, high = summary.get(f"{key}_ci95", (0, 0))
        return f"{value:.1f} %  (95 % CI {low:.1f}-{high:.1f})" if value is not None else "-"

    rows = [
        ("rounds", str(summary["rounds"])),
        ("grasp attempts", f"{summary['attempts']} ({summary['successes']} successful)"),
        ("success rate", pct("success_rate")),
        (
            "percent cleared",
            pct("percent_cleared") + f"  [{summary['objects_cleared']}/{summary['objects_placed']}]",
        ),
        ("failures", failure_breakdown(summary)),
        ("rounds ended", endings_breakdown(summary)),
        ("planning (service)", ms("planning_ms")),
        ("planning (client)", ms("client_planning_ms")),
        ("integration / attempt", ms("integration_ms")),
        (
            "time per round",
            f"{summary['round_seconds']['mean']:.1f} s" if summary.get("round_seconds") else "-",
        ),
    ]
    width = max(len(name) for name, _ in rows)
    return "\n".join(f"{name:<{width}}  {value}" for name, value in rows)
