from setuptools import find_packages, setup

package_name = "woody_sim"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    package_data={package_name: ["meshes/*.obj", "meshes/LICENSE", "meshes/README.md"]},
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="woody developers",
    maintainer_email="woody@example.org",
    description="Digital twin of a poultry conveyor line: pybullet physics, fillet models, cameras.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "line_sim = woody_sim.line_sim_node:main",
        ],
    },
)
