"""Files on disk: VGN's raw dataset layout and atomic writes.

Its own package because the simulator writes datasets, training reads them and the service
saves models, none of which belongs to the robot-side client. Needs only numpy (and the wire
schemas in ``client``), so the light client install carries it too.
"""
