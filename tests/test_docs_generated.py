"""The generated pages (docs/generated/) and the README's results block are what
``python -m benchmarks.report`` makes from the files in the repository today: the settings, the
OpenAPI document, the model card and the result files under docs/results/."""

from __future__ import annotations

from benchmarks import report


def test_generated_pages_are_current():
    outputs = report.render_all(report.RESULTS, report.GENERATED, report.README)
    stale = [str(path.relative_to(report.ROOT)) for path in report.stale(outputs)]
    assert not stale, f"out of date: {stale}; run `python -m benchmarks.report` and commit the result"
