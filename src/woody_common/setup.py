from setuptools import find_packages, setup

package_name = "woody_common"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    # the calibration the nodes and commands fall back to (woody_common.calibration.installed_calibration);
    # in the repository a link to config/calibration.yaml, copied into a built package
    package_data={package_name + ".config": ["calibration.yaml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="woody developers",
    maintainer_email="woody@example.org",
    description="What every woody package shares: calibration data, ROS parameter helpers, line constants.",
    license="Apache-2.0",
)
