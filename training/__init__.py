"""Training VGN on raw VGN datasets (docs/conventions.md): grids, loss, metrics, loop, model card.

Offline, and its own package beside ``service`` because it evaluates models in the simulator
(``sim_worker``), which the server never needs (docs/architecture.md).

Entry points: ``vgn-train`` (``training.cli:main``), ``vgn-pack-data`` (``training.pack:main``)
and ``vgn-data`` (``training.data_cli:main``).
"""
