"""PyBullet simulation worker: drives the service through the client library, and holds the
simulator commands that ``vgn-client`` dispatches to (``clear_scene``, ``generate_data``)."""
