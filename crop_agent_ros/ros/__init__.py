"""The ROS 2 side of the agents: the agent node (:mod:`.agent_node`, :mod:`.agent`), the simulator's client
(:mod:`.sim_client`), the Gymnasium bridge over ROS (:mod:`.bridge`), the farm job (:mod:`.farm`: a simulator
and an agent node in their own processes), process control (:mod:`.process`), spinning helpers (:mod:`.spin`)
and the ROS benchmark (:mod:`.bench`). Only this subpackage imports rclpy; policies and learning never import
it."""
