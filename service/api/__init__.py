"""The HTTP front end: routes, error handlers, body-size limit, metrics and the viewer page."""
