"""The gRPC front end (``vgn.v1.GraspPlanning``), beside the HTTP app over the same core."""
