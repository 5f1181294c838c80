"""PyBullet simulation worker: drives the service through the client library (see issue 3)."""
