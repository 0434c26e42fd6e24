from glob import glob

from setuptools import find_packages, setup

package_name = "qt_controller"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    # The gesture files travel inside the Python package (found with importlib.resources)
    # and are also installed to share/ for `ros2 pkg prefix`-style lookups on a full ROS 2.
    package_data={package_name + ".gesture_files": ["*.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml", "README.md"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/gestures", glob(package_name + "/gesture_files/*.xml")),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="HRI Physio maintainers",
    maintainer_email="maintainers@hri-physio.invalid",
    description="Robot side of HRI Physio: command protocol, QT robot controller and mock QT robot",
    license="BSD-3-Clause",
    entry_points={
        "console_scripts": [
            "qt_controller = qt_controller.nodes.qt_controller:main",
            "mock_qt_robot = qt_controller.nodes.mock_qt_robot:main",
        ],
    },
)
