"""Training VGN on raw VGN datasets (docs/conventions.md): grids, loss, metrics, loop, model card.

Entry point: ``vgn-train`` (``service.training.cli:main``).
"""
