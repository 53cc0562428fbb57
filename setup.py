"""ament_python package of the simulated farm; also a plain pip-installable Python package.

``colcon build`` on a ROS 2 Jazzy machine installs the ament index marker, package.xml, launch and
parameter files under share/crop_sim_ros, and the executables under lib/crop_sim_ros (``ros2 run``).
``pip install .`` installs the same nodes as console scripts.
"""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "crop_sim_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=["crop_sim_ros", "crop_sim_ros.*", "crop_agent_ros", "crop_agent_ros.*"]),
    package_data={"crop_agent_ros": ["policies/*.zip", "policies/*.json", "agents/*/*/model.zip",
                                     "agents/*/*/model.json", "learning/hyperparams/*.yml"],
                  "crop_sim_ros": ["weather/*.json", "task/scenarios/*.yaml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/launch", glob("launch/*.py")),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/msg_examples", glob("msg_examples/*.yaml")),
        # wrappers so that `ros2 run crop_sim_ros sim_node` / `agent_node` find the nodes (executable bit kept)
        (f"lib/{PACKAGE}", ["scripts/sim_node", "scripts/agent_node"]),
    ],
    python_requires=">=3.11",
    install_requires=["numpy", "gymnasium", "refet", "PyYAML", "matplotlib", "pydantic>=2"],
    # crop_sim_ros.task.jax_env and the JAX ES learner (CPU by default; jax[cuda12] for a GPU)
    extras_require={"jax": ["jax>=0.10", "evosax>=0.3.2", "optax>=0.2.8"]},
    zip_safe=True,
    maintainer="Simulated farm team",
    maintainer_email="farm@example.org",
    description="The SIMPLE crop model as ROS 2 Jazzy nodes and a Gymnasium irrigation task",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "crop-sim = crop_agent_ros.cli:main",
            "sim_node = crop_sim_ros.sim_node:main",
            "agent_node = crop_agent_ros.ros.agent_node:main",
        ],
    },
)
