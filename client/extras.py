"""One wording for a feature whose optional extra is not installed, naming the install that fixes it."""

from __future__ import annotations


def missing_extra(feature: str, extra: str, error: ImportError | None = None, then: str = "") -> str:
    """``"FEATURE needs the EXTRA extra (what failed): pip install 'vgn-service[EXTRA]'THEN"``, for the
    error each caller raises or prints (``then`` adds what else would do, e.g. ``", or ..."``)."""
    cause = f" ({error})" if error is not None else ""
    return f"{feature} needs the {extra} extra{cause}: pip install 'vgn-service[{extra}]'{then}"
