"""Helpers shared by the tests: analytic scenes, small datasets, frame uploads, runs, a browser.

Test modules import from here (``from tests.helpers.scenes import BoxScene``), never from one
another; fixtures live in ``tests/conftest.py``.
"""
