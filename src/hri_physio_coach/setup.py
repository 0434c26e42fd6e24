from glob import glob

from setuptools import find_packages, setup

package_name = "hri_physio_coach"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml", "README.md"]),
        # coach.yaml and the exercise routine; found here on a full ROS 2 install and next to
        # the package in a source / editable install (hri_physio_coach.paths).
        ("share/" + package_name + "/config", glob("config/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="HRI Physio maintainers",
    maintainer_email="maintainers@hri-physio.invalid",
    description="Scenario engine, QT cardio-aware exercise coach and simulated participant",
    license="BSD-3-Clause",
    entry_points={
        "console_scripts": [
            "qt_physio_coach = hri_physio_coach.nodes.qt_physio_coach:main",
            "simulated_participant = hri_physio_coach.nodes.simulated_participant:main",
            "hri_physio_session = hri_physio_coach.session:main",
            "hri_physio_report = hri_physio_coach.report.cli:main",
            "hri_physio_evaluate = hri_physio_coach.evaluate.cli:main",
        ],
    },
)
