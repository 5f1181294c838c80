"""The session viewer: a self-contained HTML page showing what the planner sees in 3D."""
