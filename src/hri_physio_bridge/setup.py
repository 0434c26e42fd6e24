from glob import glob

from setuptools import find_packages, setup

package_name = "hri_physio_bridge"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml", "README.md"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="HRI Physio maintainers",
    maintainer_email="maintainers@hri-physio.invalid",
    description="LSL / ROS 2 / CSV bridge for physiological signals",
    license="BSD-3-Clause",
    entry_points={
        "console_scripts": [
            "physio_receiver = hri_physio_bridge.nodes.physio_receiver:main",
            "physio_simulator = hri_physio_bridge.nodes.physio_simulator:main",
            "polar_streamer = hri_physio_bridge.nodes.polar_streamer:main",
            "physio_recorder = hri_physio_bridge.nodes.recorder:main",
            "physio_replayer = hri_physio_bridge.nodes.replayer:main",
            "physio_bridge_demo = hri_physio_bridge.demo:main",
            # The earlier names, kept working: users and scripts already type them.
            "recorder = hri_physio_bridge.nodes.recorder:main",
            "replayer = hri_physio_bridge.nodes.replayer:main",
            "hri_physio_demo = hri_physio_bridge.demo:main",
        ],
    },
)
