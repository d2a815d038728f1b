"""ROS 2 over DDS without a ROS install: our controllers as a node (`serve`), the simulated Husky
as a DDS robot, and the rehearsal that joins the two across processes (`rehearse`)."""
