from setuptools import find_packages, setup

package_name = "woody_vision"

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
    description="Top-down segmentation, tracking and woody-breast grading of fillets; reject gate.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "segmenter = woody_vision.segmenter_node:main",
            "grader = woody_vision.grader_node:main",
            "reject_gate = woody_vision.reject_gate_node:main",
        ],
    },
)
