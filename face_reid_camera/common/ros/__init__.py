"""ROS code both packages' nodes use: the lifecycle base, sealing on the wire, service calls, the floor-map topic."""
