"""``benchmarks.grasp_outcomes``: every candidate grasp of a real clutter-removal round executed in
PyBullet against a real service, with the surface's pairs, stored, resumed and replayed through the
checks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks import grasp_outcomes
from sim_worker.grasping import Outcome


@pytest.mark.slow
def test_a_round_is_collected_resumed_and_reported(tmp_path: Path, capsys):
    out = tmp_path / "outcomes"
    argv = ["collect", "--scene", "blocks", "--objects", "blocks", "--object-count", "3", "--rounds", "1",
            "--seed", "3", "--pairs", "4", "--out", str(out)]  # fmt: skip
    assert grasp_outcomes.main(argv) == 0
    stored = out / "round0000.npz"
    written = stored.read_bytes()
    looks = grasp_outcomes.load_looks(out)
    assert looks, "a round looks at least once"
    for look in looks:
        grasps, outcomes = look["grasps"], look["outcomes"]
        assert grasps.shape == (len(outcomes), 10) and look["grid"].shape == (40, 40, 40)
        assert (
            look["cloud"].ndim == 2 and look["cloud"].shape[1] == 6 and len(look["cloud"])
        )  # points, normals
        assert np.all(grasps[:, 8] >= 0.5), "candidates are the grasps of quality >= 0.5"
        assert set(np.unique(grasps[:, 9])) <= {0.0, 1.0}
        assert np.all((outcomes >= 0) & (outcomes < len(Outcome)))
        assert Outcome.INTERRUPTED not in {list(Outcome)[o] for o in outcomes}
        # How many of the three blocks the closing hand touched; a success held at least one.
        assert look["closed_on"].shape == outcomes.shape and np.all(
            (look["closed_on"] >= 0) & (look["closed_on"] <= 3)
        )
        assert np.all(look["closed_on"][outcomes == list(Outcome).index(Outcome.SUCCESS)] >= 1)
        pairs = look["pairs"]  # the surface's clearance-checked pairs, four at most, each executed
        assert pairs.shape == (len(look["pair_outcomes"]), 10) and len(pairs) <= 4
        assert look["pair_closed_on"].shape == look["pair_outcomes"].shape
        assert np.all(pairs[:, 8] >= 0.5) and np.all(pairs[:, 9] == 1.0)
    assert any(len(look["outcomes"]) for look in looks)
    capsys.readouterr()
    assert grasp_outcomes.main(argv) == 0, "a rerun resumes"
    assert "round 0" not in capsys.readouterr().out and stored.read_bytes() == written
    report_argv = ["report", str(out), str(out), "--alignments", "0.0", "0.5", "--preferred", "0.5", "0.95",
                   "--grid-angles", "1", "40", "--antipodal-angles", "1", "30", "--clearance-margins", "0.002", "0.004",
                   "--fine-min-points", "2", "10"]  # fmt: skip
    assert grasp_outcomes.main(report_argv) == 0
    report = capsys.readouterr().out
    assert f"{2 * len(looks)} looks" in report and "min alignment | kept" in report  # the folder twice
    assert "as the grid shows them" in report and "by their horizontal normal" in report
    assert "objects the hand closed on" in report
    assert "whether the table past the cube's sides vetoes them" in report
    thresholds, preferences = report.split("preferred alignment |")
    # Each threshold splits the same grasps into kept and dropped ones.
    lines = [line.split("|") for line in thresholds.splitlines() if line.strip().startswith(("0.00", "0.50"))]
    totals = {int(kept) + int(dropped) for _, kept, _, dropped, _ in lines}
    assert len(totals) == 1, "every threshold splits the same grasps"
    # A preference keeps a subset of each look's answer, never none of it.
    (_, looks_all, _, grasps_all), (_, looks_square, _, grasps_square) = [
        line.split("|") for line in preferences.split("\n\n")[0].splitlines()[1:] if line.strip()
    ]
    assert int(looks_all) == int(looks_square)
    assert float(grasps_square) <= float(grasps_all)
    # Each cone of the antipodal check, on the grid's faces, on the fine cloud and on the two in turn,
    # splits the grasps that pass both checks into opposed and not; a 1-degree cone finds fewer opposed
    # than a wider one.
    tables = [part.split("\n\n")[0] for part in report.split("cone (deg)")[1:]]
    assert len(tables) == 3, report
    rows = [[line.split("|") for line in table.splitlines()[1:] if line.strip()] for table in tables]
    totals = {int(row[1]) + int(row[3]) for table in rows for row in table}
    assert len(totals) == 1, "every cone splits the same grasps"
    for table in rows:
        assert len(table) == 2 and int(table[0][1]) <= int(table[1][1])
    # The network-first orders answer the same looks (they differ in what answers), each compared with
    # the service's; the baseline answers only where a checked pair exists, so no more looks; grasps
    # cleared on the grid's surface alone are a superset of those cleared on the fine cloud too.
    orders = report.split("a random grasp of each look's answer:")[1].split("\n\n")[0].splitlines()[2:]
    assert len(orders) == 6, report
    answered = [int(line.split("|")[1]) for line in orders]
    assert len(set(answered[:3])) == 1, report
    assert answered[3] <= answered[0] <= answered[4] <= answered[5]
    assert all("paired over" in line.split("|")[4] for line in orders[1:]), report
    # The network's grasps of each answer, split by the fine cloud's clearance check into kept and dropped;
    # more points to veto one keep at least as many.
    fine = report.split("points | answer | grasps |")[1].split("\n\n")[0].strip().splitlines()[1:]
    rows = [line.split("|") for line in fine]
    assert len(rows) == 8 and [int(row[0]) for row in rows] == [2] * 4 + [10] * 4, report
    assert all(int(row[2]) == int(row[4]) + int(row[6]) for row in rows)
    assert all(int(few[4]) <= int(many[4]) for few, many in zip(rows[:4], rows[4:], strict=True))
    # Each margin of the clearance check, its pairs cleared on the grid's surface and on the fine cloud
    # too, against the first margin on the grid's surface (itself: nothing differs). A wider hand
    # answers no more looks.
    margins = report.split("margin (mm) | pairs cleared")[1].split("\n\n")[0].strip().splitlines()[1:]
    assert len(margins) == 4, report
    assert "(0 differ)" in margins[0] and all("paired over" in line for line in margins)
    answered = [int(line.split("|")[2]) for line in margins]
    assert answered[1] <= answered[0] and answered[2] <= answered[0] and answered[3] <= answered[2]
    # The surface carried on past the cube's sides, against not: what it adds can only veto grasps.
    vetoes = report.split("grasps | clear | success % | vetoed")[1].split("\n\n")[0].strip().splitlines()[1:]
    assert [line.split("|")[0].strip() for line in vetoes] == ["network's grasps", "surface's pairs"], report
    assert all(int(line.split("|")[3]) <= int(line.split("|")[1]) for line in vetoes)
    sides = report.split("surface | looks answered |")[1].split("\n\n")[0].strip().splitlines()[1:]
    assert [line.split("|")[0].strip() for line in sides] == ["not carried on", "carried on past the sides"]
    assert int(sides[1].split("|")[1]) <= int(sides[0].split("|")[1]) and "paired over" in sides[1], report
    # Narrowing the pairs to each share of the opening, then every executed pair split at the default share.
    shares = report.split("share of the opening |")[1].split("\n\n")[0].splitlines()[1:]
    assert len(shares) == 5, report
    split = report.split("pairs | executed | success % | slipped %")[1].split("\n\n")[0].strip().splitlines()
    executed = sum(len(look["pair_outcomes"]) for look in looks)
    assert sum(int(line.split("|")[1]) for line in split) == 2 * executed  # the folder twice
