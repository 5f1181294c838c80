"""The grasp-planning service. Importing it first ends this process with the one that started
it, when that one asked (``client.embedded``), and sets the OpenMP defaults the network runs
best with (see ``service.runtime``), before anything loads torch."""

from client.lifetime import end_with_parent_if_asked
from service.runtime import prepare_environment

end_with_parent_if_asked()
prepare_environment()
