"""Starting the service in processes of its own: one child on a free port (``embedded``), a
fleet of them behind HAProxy (``fleet``, ``haproxy``), ``vgn-client serve`` (``serve``), and
children that end with their parent however it ends (``lifetime``).

It lives beside the server it starts but imports none of it: the simulator, training, the ROS
bridge and the tests start services from here with the base install's packages alone (httpx and
the wire contract), and the service's own dependencies load only in the child.
"""
