"""crop_sim_ros: the SIMPLE crop model (Zhao et al. 2019) as a simulated farm.

Layers (data flows one way; each imports only the ones before it):

- ``crop_sim_ros.model``: the pure crop model (parameters, state, one-day step for N fields, ET0).
- ``crop_sim_ros.weather``: daily weather series, file readers, the seeded generator, forecasts.
- ``crop_sim_ros.task``: the irrigation task (scenarios, observation, reward) and its Gymnasium faces.
- ``crop_sim_ros.validation``: the SIMPLE reference input set and the RRMSE report.
- ``crop_sim_ros.sim_node``: the ROS 2 simulator node, a thin adapter over ``task``.

``model`` and ``weather`` import neither rclpy, gymnasium nor torch.
"""

__version__ = "0.1.0"
