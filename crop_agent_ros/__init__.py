"""crop_agent_ros: agents for the simulated farm (policies, the ROS agent node, the Gymnasium bridge over
ROS, training and evaluation) and the ``crop-sim`` command line, which reaches every job.

The command line lives here, in the last layer, because it reaches every layer: the farm
(``crop_sim_ros``) never imports its farmers.
"""
