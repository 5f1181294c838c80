"""The VGN paper's clutter-removal figures (Breyer et al., CoRL 2020, Table 1), which every
benchmark table is read beside. A module of its own so that the report needs no simulator."""

#: VGN at threshold 0.9 (random selection): (success %, cleared %).
PAPER_TABLE_1 = {
    "blocks-5": (87.6, 90.1),
    "pile-5": (62.3, 46.4),
    "packed-5": (87.6, 80.4),
    "pile-10": (59.3, 34.6),
}
#: The GPD baseline (its best-ranked grasp): (success %, cleared %).
PAPER_GPD = {
    "blocks-5": (88.6, 39.4),
    "pile-5": (59.9, 26.1),
    "packed-5": (73.7, 72.8),
    "pile-10": (63.1, 17.0),
}
#: The paper's scenarios, in its order.
SCENARIOS = ["blocks-5", "pile-5", "packed-5", "pile-10"]
