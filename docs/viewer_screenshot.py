"""Make docs/viewer.png: a simulated blocks scene, planned by the packaged model, in the viewer.

    PYTHONPATH=. python docs/viewer_screenshot.py [--out docs/viewer.png]

Renders VGN's six views of a seeded blocks table in PyBullet, posts them to an embedded service
and screenshots /sessions/{id}/view in headless Chromium (the same browser set-up as the tests).
"""

from __future__ import annotations

import argparse
import io
from pathlib import Path

import numpy as np
from PIL import Image
from selenium.webdriver.support.ui import WebDriverWait

from client.http import VGNClient
from service.launch.embedded import EmbeddedService
from sim_worker.camera import SIM_INTRINSICS, Camera, six_views
from sim_worker.objects import object_set
from sim_worker.scenes import generate_scene
from sim_worker.world import World
from tests.helpers.browser import headless_chromium


def main() -> None:
    """Render the scene, fuse it in an embedded service and
    save the viewer's screenshot with the best grasp picked."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("docs/viewer.png"))
    parser.add_argument("--seed", type=int, default=3)
    args = parser.parse_args()
    world = World()
    try:
        generate_scene(world, "blocks", object_set("", "blocks"), 5, np.random.default_rng(args.seed))
        camera = Camera(world)
        views = [(camera.render_depth(pose), pose) for pose in six_views()]
    finally:
        world.close()
    with EmbeddedService() as service, VGNClient(service.url) as vgn:
        session = vgn.create_session(session_id="blocks-demo", intrinsics=SIM_INTRINSICS).session_id
        for depth, pose in views:
            vgn.add_frame(session, depth, pose)
        with headless_chromium() as driver:
            driver.get(f"{service.url}/sessions/{session}/view?max_grasps=10&refresh=0")
            WebDriverWait(driver, 60).until(
                lambda d: d.execute_script("return document.body.dataset.rendered")
            )
            driver.execute_script("document.querySelector('#grasp-rows tr').click()")
            shot = Image.open(io.BytesIO(driver.get_screenshot_as_png())).convert("RGB")
    shot.quantize(colors=128).save(args.out, optimize=True)
    print(f"wrote {args.out} ({args.out.stat().st_size // 1024} KiB)")


if __name__ == "__main__":
    main()
