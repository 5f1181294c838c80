"""The grasp-planning service. Importing it changes nothing in the process: the server's own
preparation (ending with its parent, the runtime defaults) happens in ``service.app``."""
