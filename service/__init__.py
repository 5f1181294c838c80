"""The grasp-planning service. Importing it first sets the OpenMP defaults the network runs
best with (see ``service.runtime``), before anything loads torch."""

from service.runtime import prepare_environment

prepare_environment()
