"""What can stop a frame from being fused, and logging each problem once instead of at camera rate."""

from __future__ import annotations

from collections.abc import Callable


class Refused(ValueError):
    """Input the bridge will not fuse. ``kind`` groups repeats of one problem (``encoding``,
    ``camera_info``, ``pose``, ``service``, ...) so that a stream of them is logged once."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


class Waiting(Refused):
    """Input that may still become fusable: the camera info or pose travels on another topic
    and can arrive after its image. Refused once a frame has waited long enough."""


class Complaints:
    """Logs each kind of problem once, until a frame is fused again: bad frames at camera rate
    leave one line saying what is wrong, not a flood that hides it."""

    def __init__(self, warn: Callable[[str], None]) -> None:
        self._warn = warn
        self._said: set[str] = set()

    def report(self, problem: Refused) -> None:
        """Log ``problem`` unless one of its kind was logged since the last fused frame."""
        if problem.kind not in self._said:
            self._said.add(problem.kind)
            self._warn(str(problem))

    def clear(self) -> None:
        """A frame was fused: a problem that comes back is news again."""
        self._said.clear()
