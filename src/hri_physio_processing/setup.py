from glob import glob

from setuptools import find_packages, setup

package_name = "hri_physio_processing"

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
    description="Streaming filters, transforms and NeuroKit2 feature extraction for physiological signals",
    license="BSD-3-Clause",
    entry_points={
        "console_scripts": [
            "neurokit_processor = hri_physio_processing.nodes.neurokit_processor:main",
        ],
    },
)
