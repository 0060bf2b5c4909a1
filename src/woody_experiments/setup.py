from setuptools import find_packages, setup

package_name = "woody_experiments"

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
    description="Headless experiments: runs, sweeps on Dask, calibration, statistics, evaluation and reports.",
    license="Apache-2.0",
)
