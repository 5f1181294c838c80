"""Executed outcomes of every candidate grasp, for choosing a grasp check's settings.

A clutter-removal benchmark executes one grasp per look, so it says how a planner does but not
which of the grasps it did *not* choose would have held. This runs clutter-removal rounds and, at
every look, executes each candidate grasp (quality at least ``--candidates``, turn-averaged, no
check) from the same saved simulator state, then advances the round as the benchmark does (a
random grasp of the default request). Each round's candidates, their outcomes, the fused grid and
the fine cloud go to ``OUT/roundNNNN.npz`` (written atomically; a rerun resumes).

    python -m benchmarks.grasp_outcomes collect --scene pile --objects OBJ/pile/train --rounds 33 --seed 11 --out DIR
    python -m benchmarks.grasp_outcomes report DIR [DIR ...]

``report`` replays the grip check (``service.grip``) on the stored grids at several alignment
thresholds and prints, among the grasps a request without it would return (quality >= 0.8 and
clearance-checked), how many it keeps and drops and how often each group succeeded; then, for
several preferred alignments, how often a random grasp of each look's answer succeeds; how many
objects the closing hand touched and how often each count succeeded; then, for
several cones of the antipodal check (``--antipodal-angles``), the same for the grasps that pass both
checks, judged by the faces their pads meet on the fine cloud. With ``collect --pairs N`` each look
also executes up to N of the surface's antipodal pairs (the service's answer where the network's
grasps fail the checks), and the report ends with how often a random grasp of each look's answer
succeeds under each order of the antipodal check's answers (``TIER_ORDERS``), with how the network's
grasps of each answer fare when cleared on the fine cloud too, with the clearance check's hand
grown by each of several margins, and with the surface taken to go on past the cube's sides or not,
and how many grasps the table taken to go on past them vetoes. Choose settings on *training* objects; benchmark on held-out ones.
"""

from __future__ import annotations

import argparse
import io
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from client.connect import connect
from service.baseline import grips_antipodally
from service.checks import (
    SUPPORT_CONTACT_TOLERANCE,
    ObservedScene,
    above_table_past_sides,
    approach_is_clear_of,
    contact_tolerances,
    observed_for_checks,
)
from service.clearance import NETWORK_FINE_MIN_POINTS, ClearanceConfig, approach_is_clear
from service.grid_surface import grid_surface_cloud, grid_surface_points
from service.grip import GripConfig, measure_grip, support_height
from service.launch.embedded import EmbeddedService
from service.settings import Settings
from sim_worker.clutter import MAX_CONSECUTIVE_FAILURES, ClutterConfig, ClutterRemoval
from sim_worker.grasping import Outcome, execute_grasp
from sim_worker.results import ResultsFolder
from vgn_contract.gripper_description import default_gripper
from vgn_contract.schemas import Grasp
from vgn_data.files import write_atomically

#: The threshold of the answer the benchmark advances with (the shipped model's operating one).
DEFAULT_THRESHOLD = 0.8
#: How outcomes are stored: their index in ``Outcome``.
OUTCOMES = list(Outcome)


def candidate_rows(grasps: list[Grasp], clear: set[tuple[float, ...]]) -> np.ndarray:
    """(G, 10) float64: position, orientation [x, y, z, w], width, quality, clearance-checked."""
    return np.array(
        [[*g.position, *g.orientation, g.width, g.quality, _key(g) in clear] for g in grasps],
        dtype=np.float64,
    ).reshape(-1, 10)


def _key(grasp: Grasp) -> tuple[float, ...]:
    return tuple(np.round(grasp.position, 5))


def collect(args: argparse.Namespace) -> int:
    """Run the rounds not stored yet in ``args.out``."""
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    config = ClutterConfig(scene=args.scene, objects=args.objects, object_count=args.object_count,
                           rounds=args.rounds, seed=args.seed, threshold=DEFAULT_THRESHOLD, selection="random",
                           noise=args.noise, views=args.views, turn_average=True, clearance=True,
                           grip=False)  # fmt: skip
    # Every candidate as the network and the clearance check give it: the antipodal check is judged in the report.
    unfiltered = {"VGN_ANTIPODAL_CHECK": "false"}
    with (
        EmbeddedService(env=unfiltered, log_path=out / "service.log") as service,
        connect(service.url) as vgn,
    ):
        episode = ClutterRemoval(config, vgn, ResultsFolder(out / "benchmark", config.as_json()))
        try:
            for round_id in range(args.rounds):
                path = out / f"round{round_id:04d}.npz"
                if not path.exists():
                    looks = run_round(episode, round_id, args.candidates, args.pairs)
                    write_atomically(path, _npz_bytes(looks))
                    print(f"round {round_id}: {len(looks)} looks, "
                          f"{sum(len(look['grasps']) for look in looks)} grasps executed", flush=True)  # fmt: skip
        finally:
            episode.close()
    return 0


def run_round(
    episode: ClutterRemoval, round_id: int, candidates: float, pairs: int = 0
) -> list[dict[str, np.ndarray]]:
    """One round: at every look, every candidate grasp executed from the same state, and with
    ``pairs`` > 0 up to that many of the surface's antipodal pairs that clear the approach (the
    round then goes on with a random pair where the network offers nothing, as the service does)."""
    rng = episode.new_scene(round_id)
    vgn, world = episode.vgn, episode.world
    looks, failures = [], 0
    while world.objects and failures < MAX_CONSECUTIVE_FAILURES:
        episode.look(rng)
        session = episode.session_id
        every = vgn.grasps(session, threshold=candidates, turn_average=True, clearance=False, grip=False,
                           max_grasps=500).grasps  # fmt: skip
        checked = vgn.grasps(session, threshold=candidates, turn_average=True, clearance=True, grip=False,
                             max_grasps=500).grasps  # fmt: skip
        look = {"grasps": candidate_rows(every, {_key(g) for g in checked}),
                **_executed(episode, every), "grid": vgn.tsdf(session), "cloud": vgn.cloud(session)}  # fmt: skip
        surface: list[Grasp] = []
        if pairs:
            # The pairs the service falls back on, down to its fallback floor; the report replays
            # the thresholds and checks that choose among them.
            surface = vgn.grasps(session, planner="antipodal", threshold=candidates, clearance=True, grip=False,
                                 max_grasps=500).grasps  # fmt: skip
            if len(surface) > pairs:  # a draw of its own: the round goes on as without pairs
                drawn = np.random.default_rng([round_id, len(looks)]).choice(
                    len(surface), pairs, replace=False
                )
                surface = [surface[i] for i in np.sort(drawn)]
            executed = _executed(episode, surface)
            look |= {"pairs": candidate_rows(surface, {_key(g) for g in surface}),
                     "pair_outcomes": executed["outcomes"], "pair_closed_on": executed["closed_on"]}  # fmt: skip
        looks.append(look)
        default = [g for g in checked if g.quality >= DEFAULT_THRESHOLD] or surface
        if not default:
            break
        trial = execute_grasp(world, episode.gripper, default[int(rng.integers(len(default)))].as_matrix())
        failures = 0 if trial.label else failures + 1
        world.wait_for_rest()
        world.remove_objects_outside()
    return looks


def _executed(episode: ClutterRemoval, grasps: list[Grasp]) -> dict[str, np.ndarray]:
    """Each grasp's ``outcomes`` (its index in ``OUTCOMES``) and how many objects the closing hand
    touched (``closed_on``: two is a grasp across neighbours), every one executed from the current state."""
    world = episode.world
    state = world.save_state()
    outcomes, closed_on = [], []
    for grasp in grasps:
        trial = execute_grasp(world, episode.gripper, grasp.as_matrix(), remove_grasped=False)
        outcomes.append(OUTCOMES.index(trial.outcome))
        closed_on.append(len(trial.closed_on))
        world.restore_state(state)
    world.discard_state(state)
    return {"outcomes": np.array(outcomes, np.int8), "closed_on": np.array(closed_on, np.int8)}


def _npz_bytes(looks: list[dict[str, np.ndarray]]) -> bytes:
    buffer = io.BytesIO()
    arrays = {f"{name}{index}": value for index, look in enumerate(looks) for name, value in look.items()}
    np.savez_compressed(buffer, looks=len(looks), **arrays)
    return buffer.getvalue()


#: What a stored look may hold (rounds collected before ``closed_on`` was recorded lack it).
LOOK_ARRAYS = ("grasps", "outcomes", "closed_on", "grid", "cloud", "pairs", "pair_outcomes", "pair_closed_on")


def load_looks(folder: Path) -> list[dict[str, np.ndarray]]:
    """Every stored look of ``folder``'s rounds."""
    looks = []
    for path in sorted(folder.glob("round*.npz")):
        with np.load(path) as data:
            looks += [{name: data[f"{name}{i}"] for name in LOOK_ARRAYS
                       if f"{name}{i}" in data} for i in range(int(data["looks"]))]  # fmt: skip
    return looks


def report(args: argparse.Namespace) -> int:
    """Print what the grip check keeps and drops of the default answer at each threshold."""
    looks = [look for folder in args.folders for look in load_looks(folder)]
    if not looks:
        print(f"no rounds in {', '.join(map(str, args.folders))}")
        return 1
    voxel_size = args.size / looks[0]["grid"].shape[0]
    success = OUTCOMES.index(Outcome.SUCCESS)
    # Each look is measured once; the thresholds only change the verdict on the measure.
    measured = []
    for look in looks:
        grasps = look["grasps"]
        answered = (grasps[:, 8] >= DEFAULT_THRESHOLD) & (grasps[:, 9] > 0)
        measure = measure_grip(
            look["grid"], voxel_size, grasps[answered, :3], grasps[answered, 3:7], support=None
        )
        measured.append((look["outcomes"][answered] == success, measure))
    rows = []
    for alignment in args.alignments:
        config = GripConfig(min_alignment=alignment)
        kept, dropped = [], []
        for held, measure in measured:
            passes = measure.passes(config)
            kept += list(held[passes])
            dropped += list(held[~passes])
        rows.append((alignment, kept, dropped))
    answered = len(rows[0][1]) + len(rows[0][2])
    everything = rows[0][1] + rows[0][2]
    print(f"{len(looks)} looks; {answered} grasps of quality >= {DEFAULT_THRESHOLD} that clear the approach, "
          f"{100 * np.mean(everything):.1f} % successful")  # fmt: skip
    print("min alignment | kept | kept success % | dropped | dropped success %")
    for alignment, kept, dropped in rows:
        print(
            f"{alignment:13.2f} | {len(kept):4d} | {_percent(kept):>14} | {len(dropped):7d} | {_percent(dropped):>17}"
        )
    print(f"\nwhere some grasps grip squarely, only those (min alignment {GripConfig().min_alignment}); over the "
          "looks the check leaves a grasp, how often a random one of them succeeds:")  # fmt: skip
    print("preferred alignment | looks | success % per look | grasps per look")
    for preferred in args.preferred:
        config = GripConfig(preferred_alignment=preferred)
        picks = [held[measure.kept(config)] for held, measure in measured]
        picks = [pick for pick in picks if len(pick)]
        per_look = [float(np.mean(pick)) for pick in picks]
        grasps = np.mean([len(pick) for pick in picks]) if picks else 0.0
        print(f"{preferred:19.2f} | {len(picks):5d} | {_percent(per_look):>18} | {grasps:15.1f}")
    print()
    closed_on_report(looks)
    print()
    support_report(looks, voxel_size)
    print()
    antipodal_report(looks, voxel_size, args.grid_angles, args.antipodal_angles)
    if any("pairs" in look for look in looks):
        print()
        with_pairs = [look for look in looks if "pairs" in look]
        pairs_report(with_pairs, voxel_size, args.pair_shares)
        print()
        fine_clearance_report(with_pairs, voxel_size, args.fine_min_points)
        print()
        margin_report(with_pairs, voxel_size, args.clearance_margins)
        print()
        sides_report(with_pairs, voxel_size)
        print()
        table_report(with_pairs, voxel_size)
    return 0


def antipodal_report(
    looks: list[dict[str, np.ndarray]], voxel_size: float, grid_angles: list[float], angles: list[float]
) -> None:
    """Print, for each cone of the antipodal check, how the grasps of quality >= the operating threshold
    that pass the clearance and grip checks fare when their pads meet opposed faces and when not, first
    on the grid's surface (``grid_angles``), then on the fine cloud (``angles``); and how often a random
    grasp of each look succeeds when the check keeps the opposed ones where there are some (the looks
    where none is opposed get the surface's pairs in the service). The last table is the service's
    check: the grid's faces within each cone first, the fine cloud's within the default cone where
    those keep none."""
    success = OUTCOMES.index(Outcome.SUCCESS)
    judged = []
    for look in looks:
        grasps = look["grasps"]
        chosen = (grasps[:, 8] >= DEFAULT_THRESHOLD) & (grasps[:, 9] > 0)
        grip = measure_grip(look["grid"], voxel_size, grasps[chosen, :3], grasps[chosen, 3:7], support="find")
        passing = np.flatnonzero(chosen)[grip.passes()]
        if len(passing):
            rotations = Rotation.from_quat(grasps[passing, 3:7]).as_matrix()
            # The simulator's workspace corner is the world's origin: grid points are world points.
            faces = {"grid": grid_surface_cloud(look["grid"], voxel_size), "cloud": look.get("cloud")}
            judged.append((faces, grasps[passing, :3], rotations, look["outcomes"][passing] == success))
    if not judged:
        print("no look with a grasp that passes both checks")
        return
    everything = [held for *_, outcomes in judged for held in outcomes]
    print(f"{len(judged)} looks with grasps of quality >= {DEFAULT_THRESHOLD} that pass both checks, "
          f"{len(everything)} grasps, {_percent(everything)} % successful, "
          f"{_percent([float(np.mean(outcomes)) for *_, outcomes in judged])} % per look")  # fmt: skip
    header = "cone (deg) | opposed | success % | not opposed | success % | success % per look | looks with none opposed"
    verdicts: dict[tuple[str, float], list[np.ndarray]] = {}
    for surface, cones in (("grid", grid_angles), ("cloud", angles)):
        if any(faces[surface] is None for faces, *_ in judged):
            print("\nno fine cloud stored (rounds collected before clouds were): the grid's faces only")
            break
        print(
            f"\njudged by the faces their pads meet on the {'grid' if surface == 'grid' else 'fine cloud'}:"
        )
        print(header)
        for angle in cones:
            keeps = [
                grips_antipodally(faces[surface], positions, rotations, None, np.radians(angle))
                for faces, positions, rotations, _ in judged
            ]
            verdicts[surface, angle] = keeps
            _cone_row(f"{angle:10.0f}", keeps, [held for *_, held in judged])
    if not any(surface == "cloud" for surface, _ in verdicts):
        return
    fine_angle = float(Settings.model_fields["antipodal_check_angle"].default)
    fine = verdicts.get(("cloud", fine_angle)) or [
        grips_antipodally(faces["cloud"], positions, rotations, None, np.radians(fine_angle))
        for faces, positions, rotations, _ in judged
    ]
    print(
        f"\nthe grid's faces first, the fine cloud's within {fine_angle:.0f} degrees where those keep none:"
    )
    print(header)
    for angle in grid_angles:
        keeps = [
            grid if grid.any() else cloud for grid, cloud in zip(verdicts["grid", angle], fine, strict=True)
        ]
        _cone_row(f"{angle:10.0f}", keeps, [held for *_, held in judged])


#: The suffix of an answer cleared on the grid's surface alone, not on the fine cloud as well.
GRID_CLEARED = " (grid-cleared)"
#: The antipodal check's answers in turn, the first that is not empty answering (``pairs_report``):
#: where some network grasp passes the clearance and grip checks (then the fallback's, where none of
#: those answers), and where none does (the fallback); and whether answering pairs are narrowed
#: (``VGN_NARROW_PAIR_SHARE``). The first is the service's.
TIER_ORDERS = {
    "the service's order": (
        ("grid", "grid pairs", "cloud", "pairs", "checked"),
        ("every grid pair", "every pair", "lower"),
        True,
    ),
    "the fine cloud before the pairs": (("grid", "cloud", "pairs", "checked"), ("every pair", "lower"), True),
    "the checked pairs before the network's grasps": (
        ("grid pairs", "grid", "cloud", "pairs", "checked"),
        ("every grid pair", "every pair", "lower"),
        True,
    ),
    "the antipodal baseline: its checked pairs alone": (("pairs",), ("pairs",), False),
    "the network's grasps cleared on the grid's surface alone": (
        ("grid", "grid pairs", "cloud" + GRID_CLEARED, "pairs", "checked" + GRID_CLEARED),
        ("every grid pair", "every pair", "lower" + GRID_CLEARED),
        True,
    ),
    "everything cleared on the grid's surface alone": (
        (
            "grid",
            "grid pairs" + GRID_CLEARED,
            "cloud" + GRID_CLEARED,
            "pairs" + GRID_CLEARED,
            "checked" + GRID_CLEARED,
        ),
        ("every grid pair" + GRID_CLEARED, "every pair" + GRID_CLEARED, "lower" + GRID_CLEARED),
        True,
    ),
}


def _order(answers: dict[str, tuple[str, np.ndarray]], checked: tuple[str, ...], fallback: tuple[str, ...]
           ) -> tuple[str, ...]:  # fmt: skip
    """The answers a look goes through in turn: where some network grasp passes the clearance and grip
    checks on the grid, ``checked`` and then, where none of those answers, the service's fallback
    ``fallback``; else ``fallback``."""
    return checked + fallback if len(answers["checked" + GRID_CLEARED][1]) else fallback


def pairs_report(
    looks: list[dict[str, np.ndarray]], voxel_size: float, shares: list[float], repeats: int = 5000
) -> None:
    """Print how often a random grasp of each look's answer succeeds under each order of the antipodal
    check's answers (``TIER_ORDERS``), from the executed network grasps and surface pairs of a
    ``collect --pairs`` run, each against the service's order paired over the looks both answer, with a
    bootstrap interval; then the service's order with its pairs narrowed to each of ``shares`` of the
    hand's opening against none narrowed, and every executed pair split by width."""
    success = OUTCOMES.index(Outcome.SUCCESS)
    grid_cone, fine_cone = (np.radians(Settings.model_fields[name].default)
                            for name in ("antipodal_check_grid_angle", "antipodal_check_angle"))  # fmt: skip
    share = Settings.model_fields["narrow_pair_share"].default
    max_opening = default_gripper().max_opening
    per_order: dict[str, list[float]] = {name: [] for name in TIER_ORDERS}
    answered_by: dict[str, dict[str, int]] = {name: {} for name in TIER_ORDERS}
    narrow: dict[float | None, list[float]] = {limit: [] for limit in [None, *shares]}
    for look in looks:
        answers = _tier_answers(look, voxel_size, grid_cone, fine_cone)
        held = {tier: look[source][rows] == success for tier, (source, rows) in answers.items()}

        for name, (checked, fallback, narrowed) in TIER_ORDERS.items():
            order = _order(answers, checked, fallback)
            tier, value = _answer(look, answers, held, order, share if narrowed else None)
            per_order[name].append(value)
            answered_by[name][tier or "nothing"] = answered_by[name].get(tier or "nothing", 0) + 1
        checked, fallback, _ = next(iter(TIER_ORDERS.values()))
        for limit in narrow:
            order = _order(answers, checked, fallback)
            narrow[limit].append(_answer(look, answers, held, order, limit)[1])
    print(f"{len(looks)} looks with the surface's pairs executed; a random grasp of each look's answer:")
    print("order | looks answered | success % per look | answered by | against the service's order")
    reference = np.array(next(iter(per_order.values())))
    for index, (name, values) in enumerate(per_order.items()):
        answered = [v for v in values if not np.isnan(v)]
        tiers = ", ".join(f"{tier} {count}" for tier, count in answered_by[name].items())
        against = _paired(reference, np.array(values), repeats) if index else "-"
        print(f"{name} | {len(answered)} | {_percent(answered)} | {tiers} | {against}")
    print(f"\nthe service's order, its pairs narrowed to those that close on at most a share of the "
          f"{max_opening * 100:.0f} cm opening where some do; against none narrowed:")  # fmt: skip
    print("share of the opening | success % per look | paired difference")
    unnarrowed = np.array(narrow.pop(None))
    for limit, values in narrow.items():
        per_look = [v for v in values if not np.isnan(v)]
        print(f"{limit:20.3f} | {_percent(per_look):>18} | {_paired(unnarrowed, np.array(values), repeats)}")
    widths = np.concatenate([look["pairs"][:, 7] for look in looks])
    outcomes = np.concatenate([look["pair_outcomes"] for look in looks])
    print(f"\nevery executed pair, by whether it closes on at most {share:.2f} of the opening:")
    print("pairs | executed | success % | slipped %")
    for label, group in (("narrow", widths <= share * max_opening), ("wide", widths > share * max_opening)):
        held_pairs = outcomes[group] == success
        slipped = outcomes[group] == OUTCOMES.index(Outcome.SLIPPED)
        print(f"{label} | {group.sum()} | {_percent(list(held_pairs))} | {_percent(list(slipped))}")


def fine_clearance_report(
    looks: list[dict[str, np.ndarray]], voxel_size: float, min_points: list[int]
) -> None:
    """Print, for the network's grasps of each answer of ``_tier_answers`` (cleared on the grid's
    surface, as collected), how many the clearance check on the fine cloud keeps and drops and how
    often each group succeeded, with each of ``min_points`` of its points vetoing a grasp. The service
    clears every answer but "grid" so, where it has read the fine cloud anyway; "grid" is shown for
    comparison."""
    success = OUTCOMES.index(Outcome.SUCCESS)
    grid_cone, fine_cone = (np.radians(Settings.model_fields[name].default)
                            for name in ("antipodal_check_grid_angle", "antipodal_check_angle"))  # fmt: skip
    labels = (
        "grid (not cleared so)",
        "checked, past the grid's faces",
        "cloud",
        "lower, below the operating threshold",
    )
    groups: dict[tuple[int, str], list[tuple[np.ndarray, np.ndarray]]] = {}
    for look in looks:
        answers = _tier_answers(look, voxel_size, grid_cone, fine_cone)
        checked, grid = answers["checked" + GRID_CLEARED][1], answers["grid"][1]
        answered = dict(zip(labels, (grid, np.setdiff1d(checked, grid), answers["cloud" + GRID_CLEARED][1],
                                     np.setdiff1d(answers["lower" + GRID_CLEARED][1], checked)), strict=True))  # fmt: skip
        held = look["outcomes"] == success
        seen = _fine_cloud_seen(look, voxel_size)
        for points in min_points:
            clear = _cleared(look["grasps"], seen, ClearanceConfig(min_points=points))
            for label, indices in answered.items():
                groups.setdefault((points, label), []).append((held[indices], clear[indices]))
    print("the network's grasps of each answer, cleared on the fine cloud too (the service's 4 mm hand), by how many "
          f"of its points veto a grasp (the service: {NETWORK_FINE_MIN_POINTS}):")  # fmt: skip
    print("points | answer | grasps | success % | kept | success % | dropped | success %")
    for (points, label), judged in groups.items():
        held = np.concatenate([h for h, _ in judged])
        kept = np.concatenate([k for _, k in judged])
        print(f"{points} | {label} | {len(held)} | {_percent(list(held))} | {kept.sum()} | {_percent(list(held[kept]))} | "
              f"{(~kept).sum()} | {_percent(list(held[~kept]))}")  # fmt: skip


def margin_report(
    looks: list[dict[str, np.ndarray]], voxel_size: float, margins: list[float], repeats: int = 5000
) -> None:
    """Print how often a random grasp of each look's answer succeeds, in the service's order, with the
    clearance check's hand grown by each of ``margins``, its pairs cleared on the grid's surface alone
    and on the fine cloud as well; each against the first margin on the grid's surface alone. A margin
    below the collection's replays only what the collection's clearance check kept."""
    grid_cone, fine_cone = (np.radians(Settings.model_fields[name].default)
                            for name in ("antipodal_check_grid_angle", "antipodal_check_angle"))  # fmt: skip
    share = Settings.model_fields["narrow_pair_share"].default
    success = OUTCOMES.index(Outcome.SUCCESS)
    orders = {"on the grid's surface": TIER_ORDERS["everything cleared on the grid's surface alone"],
              "on the fine cloud too": next(iter(TIER_ORDERS.values()))}  # fmt: skip
    values: dict[tuple[float, str], list[float]] = {}
    for look in looks:
        for margin in margins:
            answers = _tier_answers(look, voxel_size, grid_cone, fine_cone, ClearanceConfig(margin=margin))
            held = {tier: look[source][rows] == success for tier, (source, rows) in answers.items()}
            for label, (checked, fallback, narrowed) in orders.items():
                order = _order(answers, checked, fallback)
                value = _answer(look, answers, held, order, share if narrowed else None)[1]
                values.setdefault((margin, label), []).append(value)
    reference = np.array(values[margins[0], "on the grid's surface"])
    print(f"the clearance check's margin, in the service's order; against {margins[0] * 1000:.0f} mm with the pairs "
          "cleared on the grid's surface alone:")  # fmt: skip
    print("margin (mm) | pairs cleared | looks answered | success % per look | against it")
    for (margin, label), per_look in values.items():
        answered = [v for v in per_look if not np.isnan(v)]
        against = _paired(reference, np.array(per_look), repeats)
        print(f"{margin * 1000:11.1f} | {label} | {len(answered)} | {_percent(answered)} | {against}")


def sides_report(looks: list[dict[str, np.ndarray]], voxel_size: float, repeats: int = 5000) -> None:
    """Print how often a random grasp of each look's answer succeeds, in the service's order, with the
    surface taken to go on past the cube's sides where it meets them (the service) and without."""
    grid_cone, fine_cone = (np.radians(Settings.model_fields[name].default)
                            for name in ("antipodal_check_grid_angle", "antipodal_check_angle"))  # fmt: skip
    share = Settings.model_fields["narrow_pair_share"].default
    success = OUTCOMES.index(Outcome.SUCCESS)
    checked, fallback, _ = next(iter(TIER_ORDERS.values()))
    values: dict[bool, list[float]] = {False: [], True: []}
    # The grasps the carried-on surface vetoes: the network's (quality >= the operating threshold) on
    # the grid's surface, the pairs on the fine cloud, as the service clears each.
    judged: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {"network's grasps": [], "surface's pairs": []}
    for look in looks:
        for past_sides in values:
            answers = _tier_answers(look, voxel_size, grid_cone, fine_cone, past_sides=past_sides)
            held = {tier: look[source][rows] == success for tier, (source, rows) in answers.items()}
            order = _order(answers, checked, fallback)
            values[past_sides].append(_answer(look, answers, held, order, share)[1])
        for label, part in _vetoed_past_sides(look, voxel_size).items():
            judged[label].append(part)
    print(
        "grasps clear of the surface as observed, by whether the surface carried on past the cube's sides vetoes them:"
    )
    print("grasps | clear | success % | vetoed | success %")
    for label, parts in judged.items():
        held = np.concatenate([h for h, _ in parts]) if parts else np.zeros(0, dtype=bool)
        vetoed = np.concatenate([v for _, v in parts]) if parts else np.zeros(0, dtype=bool)
        print(
            f"{label} | {len(held)} | {_percent(list(held))} | {vetoed.sum()} | {_percent(list(held[vetoed]))}"
        )
    print("\nthe surface taken to go on past the cube's sides where it meets them, in the service's order:")
    print("surface | looks answered | success % per look | against not carried on")
    reference = np.array(values[False])
    for past_sides, per_look in values.items():
        answered = [v for v in per_look if not np.isnan(v)]
        against = _paired(reference, np.array(per_look), repeats) if past_sides else "-"
        label = "carried on past the sides" if past_sides else "not carried on"
        print(f"{label} | {len(answered)} | {_percent(answered)} | {against}")


def table_report(looks: list[dict[str, np.ndarray]], voxel_size: float) -> None:
    """Print how many executed grasps the table taken to go on past the cube's sides vetoes, and how
    those fared: the network's (quality >= the operating threshold) and the surface's pairs, each
    clear of the observed surface, on looks where the support plane is found."""
    success = OUTCOMES.index(Outcome.SUCCESS)
    print("grasps clear of the surface, by whether the table past the cube's sides vetoes them:")
    print("grasps | clear | success % | vetoed | success %")
    for label, rows, outcomes in (
        ("network's grasps", "grasps", "outcomes"),
        ("surface's pairs", "pairs", "pair_outcomes"),
    ):
        held, vetoed = [], []
        for look in looks:
            grid = look["grid"]
            seen = observed_for_checks(None, grid, voxel_size, np.eye(4), voxel_size * grid.shape[0])
            chosen = look[rows][:, 9] > 0
            if label == "network's grasps":
                chosen &= look[rows][:, 8] >= DEFAULT_THRESHOLD
            if seen.support is None or not chosen.any():
                continue
            grasps = look[rows][chosen]
            above = above_table_past_sides(grasps[:, :3], grasps[:, 3:7], seen)
            held += list(look[outcomes][chosen] == success)
            vetoed += list(~above)
        held_arr, vetoed_arr = np.array(held, dtype=bool), np.array(vetoed, dtype=bool)
        print(f"{label} | {len(held)} | {_percent(held)} | {int(vetoed_arr.sum())} | "
              f"{_percent(list(held_arr[vetoed_arr]))}")  # fmt: skip


def _vetoed_past_sides(
    look: dict[str, np.ndarray], voxel_size: float
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Of a look's network grasps (quality >= the operating threshold, cleared on the grid's surface)
    and its surface's pairs (cleared on the fine cloud), those clear of the surface as observed:
    whether each held, and whether the surface carried on past the cube's sides vetoes it."""
    grid, size = look["grid"], voxel_size * look["grid"].shape[0]
    surface = grid_surface_points(grid, voxel_size)
    answered = (look["grasps"][:, 8] >= DEFAULT_THRESHOLD) & (look["grasps"][:, 9] > 0)
    success = OUTCOMES.index(Outcome.SUCCESS)
    judged = {}
    for label, rows, outcomes, observed, carried in (
        ("network's grasps", look["grasps"][answered], look["outcomes"][answered],
         observed_for_checks(surface, grid, voxel_size, np.eye(4), size, past_sides=False),
         observed_for_checks(surface, grid, voxel_size, np.eye(4), size)),
        ("surface's pairs", look["pairs"], look["pair_outcomes"],
         _fine_cloud_seen(look, voxel_size, past_sides=False), _fine_cloud_seen(look, voxel_size)),
    ):  # fmt: skip
        clear = _cleared(rows, observed, ClearanceConfig()) if len(rows) else np.zeros(0, dtype=bool)
        vetoed = clear & ~_cleared(rows, carried, ClearanceConfig()) if len(rows) else clear
        judged[label] = (outcomes[clear] == success, vetoed[clear])
    return judged


def _answer(
    look: dict[str, np.ndarray],
    answers: dict[str, tuple[str, np.ndarray]],
    held: dict[str, np.ndarray],
    order: tuple[str, ...],
    limit: float | None,
) -> tuple[str | None, float]:
    """The tier of ``order`` that answers a look and the success of a random grasp of it, its pairs
    narrowed to those within ``limit`` of the hand's opening where some are (None: not narrowed)."""
    tier = next((tier for tier in order if len(held[tier])), None)
    if tier is None:
        return None, np.nan
    source, rows = answers[tier]
    kept = held[tier]
    if limit is not None and source == "pair_outcomes":
        within = look["pairs"][rows, 7] <= limit * default_gripper().max_opening
        kept = kept[within] if within.any() else kept
    return tier, float(np.mean(kept))


def _paired(first: np.ndarray, second: np.ndarray, repeats: int) -> str:
    """The mean per-look difference of ``second`` over ``first`` with a bootstrap interval."""
    both = ~np.isnan(first) & ~np.isnan(second)
    difference = second[both] - first[both]
    draws = np.random.default_rng(0).choice(difference, (repeats, len(difference))).mean(axis=1)
    low, high = np.percentile(draws, [2.5, 97.5]) * 100
    return (f"paired over {both.sum()} looks ({np.count_nonzero(difference)} differ): {100 * difference.mean():+.1f} "
            f"points per look (95 % bootstrap interval {low:+.1f} to {high:+.1f})")  # fmt: skip


def _tier_answers(
    look: dict[str, np.ndarray],
    voxel_size: float,
    grid_cone: float,
    fine_cone: float,
    clearance: ClearanceConfig = ClearanceConfig(),  # noqa: B008 (frozen: one shared default is safe)
    past_sides: bool = True,
) -> dict[str, tuple[str, np.ndarray]]:
    """Each candidate answer of one look, as (outcomes key, row indices): the network's grasps that
    pass both checks ("checked"), those opposed on the grid's faces ("grid") or the fine cloud
    ("cloud"); the pairs that pass the grip check ("pairs") and those opposed on the grid's faces
    ("grid pairs"); every clearance-checked pair ("every pair", "every grid pair"); and the network's
    grasps that pass both checks down to the fallback floor ("lower"). The clearance check is replayed
    with ``clearance`` on the grid's surface, as collected (so a margin below the collection's keeps
    what the collection kept). The service clears its pairs on the fine cloud as well, and the
    network's grasps wherever it has read that cloud (every answer but "grid", ``NETWORK_FINE_MIN_POINTS``
    of its points vetoing one), so each of those answers does too, and is also given on the grid's surface
    alone, :data:`GRID_CLEARED` appended. Without ``past_sides`` the surface is not taken to go on past
    the cube's sides (the service before)."""
    grid, grasps, pairs = look["grid"], look["grasps"], look["pairs"]
    faces = grid_surface_cloud(grid, voxel_size)

    def gripping(rows: np.ndarray, indices: np.ndarray) -> np.ndarray:
        if not len(indices):
            return indices
        return indices[
            measure_grip(grid, voxel_size, rows[indices, :3], rows[indices, 3:7], support="find").passes()
        ]

    def opposed(rows: np.ndarray, indices: np.ndarray, cloud: np.ndarray, cone: float) -> np.ndarray:
        if not len(indices):
            return indices
        rotations = Rotation.from_quat(rows[indices, 3:7]).as_matrix()
        return indices[grips_antipodally(cloud, rows[indices, :3], rotations, None, cone)]

    size = voxel_size * grid.shape[0]
    surface = observed_for_checks(
        grid_surface_points(grid, voxel_size), grid, voxel_size, np.eye(4), size, past_sides=past_sides
    )
    grasps_clear = (grasps[:, 9] > 0) & _cleared(grasps, surface, clearance)
    checked = gripping(grasps, np.flatnonzero((grasps[:, 8] >= DEFAULT_THRESHOLD) & grasps_clear))
    every_pair = np.flatnonzero(_cleared(pairs, surface, clearance))
    gripping_pairs = gripping(pairs, every_pair)
    pair_answers = {
        "pairs": gripping_pairs,
        "grid pairs": opposed(pairs, gripping_pairs, faces, grid_cone),
        "every pair": every_pair,
        "every grid pair": opposed(pairs, every_pair, faces, grid_cone),
    }
    fine_cloud = _fine_cloud_seen(look, voxel_size, past_sides)
    pairs_fine_clear = _cleared(pairs, fine_cloud, clearance)
    grasps_fine_clear = _cleared(grasps, fine_cloud, replace(clearance, min_points=NETWORK_FINE_MIN_POINTS))
    network_answers = {
        "checked": checked,
        "cloud": opposed(grasps, checked, look["cloud"], fine_cone),
        "lower": gripping(grasps, np.flatnonzero(grasps_clear)),
    }
    return {
        "grid": ("outcomes", opposed(grasps, checked, faces, grid_cone)),
        **{name: ("outcomes", rows[grasps_fine_clear[rows]]) for name, rows in network_answers.items()},
        **{name + GRID_CLEARED: ("outcomes", rows) for name, rows in network_answers.items()},
        **{name: ("pair_outcomes", rows[pairs_fine_clear[rows]]) for name, rows in pair_answers.items()},
        **{name + GRID_CLEARED: ("pair_outcomes", rows) for name, rows in pair_answers.items()},
    }


def _fine_cloud_seen(
    look: dict[str, np.ndarray], voxel_size: float, past_sides: bool = True
) -> ObservedScene:
    """A look's fine cloud as the service's clearance check judges against it (its points' spacing:
    the service's default fine volume's), ``past_sides`` as :func:`_tier_answers` takes it."""
    grid = look["grid"]
    size = voxel_size * grid.shape[0]
    spacing = size / Settings.model_fields["cloud_resolution"].default
    cloud = look["cloud"][:, :3].astype(np.float64)
    return observed_for_checks(
        cloud, grid, voxel_size, np.eye(4), size, spacing=spacing, past_sides=past_sides
    )


def _cleared(rows: np.ndarray, seen: ObservedScene, clearance: ClearanceConfig) -> np.ndarray:
    """(G,) bool: which grasp ``rows`` (position, orientation first) the clearance check passes on
    what ``seen`` holds (the cube's frame)."""
    if seen.surface is None:
        return np.ones(len(rows), dtype=bool)
    return approach_is_clear_of(rows[:, :3], rows[:, 3:7], replace(seen, clearance=clearance))


def _cone_row(label: str, keeps: list[np.ndarray], outcomes: list[np.ndarray]) -> None:
    """One row of a cone table: the opposed and other grasps' success, and per look."""
    opposed = [h for keep, held in zip(keeps, outcomes, strict=True) for h in held[keep]]
    other = [h for keep, held in zip(keeps, outcomes, strict=True) for h in held[~keep]]
    per_look = [
        float(np.mean(held[keep] if keep.any() else held)) for keep, held in zip(keeps, outcomes, strict=True)
    ]
    without = sum(not keep.any() for keep in keeps)
    print(f"{label} | {len(opposed):7d} | {_percent(opposed):>9} | {len(other):11d} | {_percent(other):>9} | "
          f"{_percent(per_look):>18} | {without}")  # fmt: skip


def closed_on_report(looks: list[dict[str, np.ndarray]]) -> None:
    """Print how many objects the closing hand touched, and how often each count succeeded: the
    network's grasps a request without the grip check would return, and the surface's pairs. A hand
    that closes on two neighbours squeezes them apart, so how common that is says whether a check for
    it could pay off on these objects."""
    stored = [look for look in looks if "closed_on" in look]
    if not stored:
        print("no closed-on counts stored (rounds collected before they were)")
        return
    success = OUTCOMES.index(Outcome.SUCCESS)
    print("grasps | objects the hand closed on | grasps | share % | success %")
    for label, rows, outcomes, counts in (("network", "grasps", "outcomes", "closed_on"),
                                          ("pairs", "pairs", "pair_outcomes", "pair_closed_on")):  # fmt: skip
        held, touched = [], []
        for look in stored:
            if counts not in look:
                continue
            chosen = np.ones(len(look[rows]), dtype=bool)
            if label == "network":
                chosen = (look[rows][:, 8] >= DEFAULT_THRESHOLD) & (look[rows][:, 9] > 0)
            held += list(look[outcomes][chosen] == success)
            touched += list(np.minimum(look[counts][chosen], 2))
        for count, name in ((0, "none"), (1, "one"), (2, "two or more")):
            group = [h for h, t in zip(held, touched, strict=True) if t == count]
            share = 100 * len(group) / max(len(held), 1)
            print(f"{label:7s}| {name:26s} | {len(group):6d} | {share:7.1f} | {_percent(group):>9}")


def support_report(looks: list[dict[str, np.ndarray]], voxel_size: float) -> None:
    """Print what judging faces by their horizontal normal just above the table (the support
    plane) changes: the grasps each way passes and grips squarely, and how often they succeeded."""
    success = OUTCOMES.index(Outcome.SUCCESS)
    print("clearance-checked grasps | faces near the table judged | passes | success % | square | success %")
    for low, high in ((DEFAULT_THRESHOLD, 1.01), (0.5, DEFAULT_THRESHOLD)):
        for label, support in (("as the grid shows them", None), ("by their horizontal normal", "find")):
            passing, square = [], []
            for look in looks:
                grasps = look["grasps"]
                chosen = (grasps[:, 8] >= low) & (grasps[:, 8] < high) & (grasps[:, 9] > 0)
                measure = measure_grip(look["grid"], voxel_size, grasps[chosen, :3], grasps[chosen, 3:7],
                                       support=support)  # fmt: skip
                held = look["outcomes"][chosen] == success
                passing += list(held[measure.passes()])
                square += list(held[measure.square()])
            band = f"quality {low:.1f}-{min(high, 1.0):.1f}"
            print(f"{band:24s} | {label:27s} | {len(passing):6d} | {_percent(passing):>9} | "
                  f"{len(square):6d} | {_percent(square):>9}")  # fmt: skip
    print("\ngrasps the clearance check drops, but clears when the fingertips may meet the table in the last "
          f"{SUPPORT_CONTACT_TOLERANCE * 1000:.0f} mm of the approach, that pass the grip check:")  # fmt: skip
    print("quality | passes | success % | square | success %")
    for low, high in ((DEFAULT_THRESHOLD, 1.01), (0.5, DEFAULT_THRESHOLD)):
        passing, square = [], []
        for look in looks:
            grasps, grid = look["grasps"], look["grid"]
            support = support_height(grid, voxel_size)
            if support is None or not len(grasps):
                continue
            surface = grid_surface_points(grid, voxel_size)
            tolerance = contact_tolerances(surface, np.eye(4), support, voxel_size, ClearanceConfig().margin)
            cleared = approach_is_clear(surface, grasps[:, :3], grasps[:, 3:7], point_tolerance=tolerance)
            added = cleared & ~approach_is_clear(surface, grasps[:, :3], grasps[:, 3:7])
            added &= (grasps[:, 8] >= low) & (grasps[:, 8] < high)
            measure = measure_grip(grid, voxel_size, grasps[added, :3], grasps[added, 3:7])
            held = look["outcomes"][added] == success
            passing += list(held[measure.passes()])
            square += list(held[measure.square()])
        band = f"{low:.1f}-{min(high, 1.0):.1f}"
        print(
            f"{band:7s} | {len(passing):6d} | {_percent(passing):>9} | {len(square):6d} | {_percent(square):>9}"
        )


def _percent(outcomes: list[bool]) -> str:
    return f"{100 * np.mean(outcomes):.1f}" if outcomes else "-"


def main(argv: list[str] | None = None) -> int:
    """``collect`` or ``report``, as the arguments say."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    commands = parser.add_subparsers(dest="command", required=True)
    run = commands.add_parser("collect", help="execute every candidate grasp of clutter-removal rounds")
    run.add_argument("--scene", choices=["pile", "packed", "blocks"], default="pile")
    run.add_argument("--objects", help="object set or URDF folder (choose settings on training objects)")
    run.add_argument("--object-count", type=int, default=5)
    run.add_argument("--rounds", type=int, default=30)
    run.add_argument("--seed", type=int, default=11)
    run.add_argument("--noise", action="store_true", help="Dex-Net depth noise on every view")
    run.add_argument("--views", choices=["six", "side"], default="six", help="six views, or one side view")
    run.add_argument("--candidates", type=float, default=0.5, help="least quality of an executed candidate")
    run.add_argument("--pairs", type=int, default=0,
                     help="also execute up to this many of the surface's antipodal pairs per look (clearance-checked)")  # fmt: skip
    run.add_argument("--out", type=Path, required=True)
    show = commands.add_parser("report", help="the grip check's verdicts against the executed outcomes")
    show.add_argument("folders", type=Path, nargs="+", help="collect's output folders, read together")
    show.add_argument("--alignments", type=float, nargs="+", default=[0.4, 0.5, 0.6, 0.7])
    show.add_argument("--preferred", type=float, nargs="+", default=[0.5, 0.6, 0.7, 0.8],
                      help="preferred alignments to compare (0.5: no preference)")  # fmt: skip
    show.add_argument("--grid-angles", type=float, nargs="+", default=[25.0, 30.0, 35.0, 40.0, 45.0],
                      help="cones (degrees) of the antipodal check on the grid's faces to compare")  # fmt: skip
    show.add_argument("--antipodal-angles", type=float, nargs="+", default=[10.0, 15.0, 20.0, 25.0, 30.0],
                      help="cones (degrees) of the antipodal check on the fine cloud to compare")  # fmt: skip
    show.add_argument("--pair-shares", type=float, nargs="+", default=[0.625, 0.6875, 0.75, 0.8125, 0.875],
                      help="shares of the hand's opening the surface's pairs may close on, to compare")  # fmt: skip
    show.add_argument("--clearance-margins", type=float, nargs="+", default=[0.002, 0.003, 0.004, 0.005],
                      help="margins (m) of the clearance check to replay, the first the reference")  # fmt: skip
    show.add_argument("--fine-min-points", type=int, nargs="+", default=[2, 5, 10, 20],
                      help="how many fine-cloud points veto a network grasp, to compare")  # fmt: skip
    show.add_argument("--size", type=float, default=0.3, help="workspace side the grids were fused in (m)")
    args = parser.parse_args(argv)
    return collect(args) if args.command == "collect" else report(args)


if __name__ == "__main__":
    raise SystemExit(main())
