"""Training VGN on raw VGN datasets (DESIGN §4, §5): grids, loss, metrics, loop, model card.

Entry point: ``vgn-train`` (``service.training.cli:main``).
"""
