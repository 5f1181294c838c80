"""The server process's entry: ``uvicorn service.app:app`` serves the application of ``service.http_app``.

Importing this module prepares the process it runs in as a server, before anything loads torch:
it ends with the process that started it when that one asked (``service.launch.embedded``, through
``service.launch.lifetime``), and sets the runtime defaults of ``service.runtime``, which libgomp reads
once, when torch loads. ``vgn-client serve``, the embedded service and the container image start
the server through here; importing ``service`` or ``service.http_app`` changes nothing in the process.
"""

from service.launch.lifetime import end_with_parent_if_asked
from service.runtime import prepare_environment

end_with_parent_if_asked()
prepare_environment()

from service.http_app import app  # noqa: E402  (after the environment is prepared: it loads torch)

__all__ = ["app"]
