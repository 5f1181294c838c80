"""A grasp request on a session whose volume has not changed reuses the last network
output: same grasps, no forward pass; any frame or reset makes the next request run it."""

from __future__ import annotations

from service.core import PlanningService
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views
from vgn_contract.schemas import GraspQuery, SessionCreate


def forwards(core: PlanningService) -> int:
    return core.planner.runtime()["batches"]["batches"]


def test_the_network_runs_again_only_when_the_volume_changed(core: PlanningService):
    session = core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
    scene, views = BoxScene(), circle_views(3)
    for pose in views[:2]:
        core.add_frame(session, scene.depth(pose), pose)
    # Without the clearance check: it drops every grasp of the random weights on this scene.
    query = GraspQuery(threshold=0.3, clearance=False, grip=False)
    start = forwards(core)
    first = core.plan(session, query)
    again = core.plan(session, query)
    other_query = core.plan(session, GraspQuery(threshold=0.5, max_grasps=2, clearance=False, grip=False))
    checked = core.plan(session, GraspQuery(threshold=0.3))
    assert forwards(core) == start + 1, "one forward for four requests on an unchanged volume"
    assert checked.clearance_dropped + checked.workspace_dropped == len(first.grasps) - len(checked.grasps)
    assert again.grasps == first.grasps and first.grasps
    assert other_query.grasps == [g for g in first.grasps if g.quality >= 0.5][:2]

    core.add_frame(session, scene.depth(views[2]), views[2])
    core.plan(session, query)
    assert forwards(core) == start + 2, "a new frame means a new forward"
    core.reset_session(session)
    assert core.plan(session, query).grasps == []
    assert forwards(core) == start + 3, "so does a reset"


def test_reuse_can_be_switched_off(settings):
    core = PlanningService.from_settings(settings.model_copy(update={"reuse_output": False}))
    session = core.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
    pose = circle_views(1)[0]
    core.add_frame(session, BoxScene().depth(pose), pose)
    start = forwards(core)
    core.plan(session, GraspQuery())
    core.plan(session, GraspQuery())
    assert forwards(core) == start + 2
