from setuptools import find_packages, setup

package_name = "woody_bag"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="woody developers",
    maintainer_email="woody@example.org",
    description="MCAP bags the rosbag2 way: writer, reader, recovery, the recorder node and the replay player.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "recorder = woody_bag.recorder_node:main",
            "foxglove_view = woody_bag.foxglove_view_node:main",
        ],
    },
)
