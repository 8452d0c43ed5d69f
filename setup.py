"""Packaging for biped_opt: an ament_python package that also installs with plain pip."""

from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

package_name = "biped_opt"
here = Path(__file__).resolve().parent


def pinned_requirements() -> list[str]:
    """Runtime pins from requirements.txt, the single place versions are chosen."""
    lines = (here / "requirements.txt").read_text().splitlines()
    return [line.strip() for line in lines if line.strip() and not line.startswith("#")]


setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(include=[package_name, f"{package_name}.*"]),
    # (the library's robots: their URDFs, licences and sources, SYSTEMS.md Sec. 3c)
    package_data={package_name: ["py.typed", "systems/library/robots/*/*",
                                # (the C runtime a kernel library is linked with)
                                "codegen/native_runtime.c"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{package_name}"]),
        (f"share/{package_name}", ["package.xml"]),
        (f"share/{package_name}/launch", sorted(glob("launch/*_launch.py"))),
        # the node parameters, the RViz2 view and the Foxglove layout
        (f"share/{package_name}/config",
         sorted(glob("config/*.yaml") + glob("config/*.rviz") + glob("config/*.json"))),
        # the interface definitions the built-in DDS backend generates its types from
        (f"share/{package_name}/msg_defs", ["msg_defs/package.xml", "msg_defs/CMakeLists.txt"]),
        (f"share/{package_name}/msg_defs/msg", sorted(glob("msg_defs/msg/*.msg"))),
        (f"share/{package_name}/msg_defs/srv", sorted(glob("msg_defs/srv/*.srv"))),
        (f"share/{package_name}/msg_defs/action", sorted(glob("msg_defs/action/*.action"))),
        # standard packages rosbags lacks, as published (with their licence): the types of
        # the simulator's ROS 2 Simulation Interfaces on the built-in backend
        *((f"share/{package_name}/{folder}", sorted(str(p) for p in Path(folder).iterdir()
                                                    if p.is_file()))
          for folder in sorted({str(p.parent) for p in Path("msg_defs/vendor").rglob("*")
                                if p.is_file()})),
    ],
    install_requires=pinned_requirements(),
    python_requires=">=3.10",
    zip_safe=False,
    maintainer="biped_opt maintainers",
    description="Nonsmooth optimal control of a biped with unilateral constraints",
    license="MIT",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "biped-opt = biped_opt.cli.main:entry",
            "simulator = biped_opt.nodes.simulator:main",
            "optimiser = biped_opt.nodes.optimiser:main",
            "recorder = biped_opt.nodes.recorder:main",
            "coordinator = biped_opt.nodes.coordinator:main",
            "foxglove_bridge = biped_opt.nodes.foxglove:main",
        ],
    },
)
