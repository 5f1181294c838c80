"""Text tables of training progress: one row per epoch, printed live and as a summary.

The quality and error columns come from the validation split, or from the training
split when the run has none (the header says which).
"""

from __future__ import annotations

from typing import Any

from training.metrics import COLUMNS, format_metric


def _shown(validation: bool) -> list[str]:
    """Metric columns after the training loss (its loss again only for validation)."""
    return [name for name in COLUMNS if validation or name != "loss"]


def header(validation: bool = True) -> str:
    """Column titles matching ``row``."""
    split = "val" if validation else "train"
    titles = ["epoch", "train loss", *(f"{split} {COLUMNS[name][0]}" for name in _shown(validation)), "s"]
    return "  ".join(f"{t:>12}" for t in titles)


def row(entry: dict[str, Any]) -> str:
    """One history entry (``{"epoch", "train", "val", "seconds"}``) as a table line."""
    train, val = entry["train"], entry.get("val")
    shown = val or train
    cells = [str(entry["epoch"]), format_metric("loss", train.get("loss"))]
    cells += [format_metric(name, shown.get(name)) for name in _shown(val is not None)]
    cells.append(f"{entry['seconds']:.1f}")
    return "  ".join(f"{c:>12}" for c in cells)


def table(history: list[dict[str, Any]]) -> str:
    """The whole history as a table, its columns from validation when the run had a validation split."""
    validation = bool(history) and history[0].get("val") is not None
    return "\n".join([header(validation), *(row(entry) for entry in history)])
