"""Dependencies point one way: the numerical core imports no ROS, plotting or file-format code."""

from __future__ import annotations

import json
import subprocess
import sys

CORE = ["biped_opt", "biped_opt.model", "biped_opt.hybrid", "biped_opt.maneuvers",
        "biped_opt.nonsmooth", "biped_opt.fixed_sweep", "biped_opt.optimal",
        "biped_opt.optimal.derivatives", "biped_opt.systems", "biped_opt.systems.problems",
        "biped_opt.systems.optimal", "biped_opt.systems.nonsmooth", "biped_opt.systems.derivatives",
        "biped_opt.systems.optimal_derivatives", "biped_opt.systems.compiled"]
FORBIDDEN = ["rclpy", "cyclonedds", "rosbags", "mcap", "mcap_ros2", "matplotlib",
             "biped_opt.ros", "biped_opt.plots", "biped_opt.nodes", "biped_opt.record"]


def test_core_imports_nothing_outside_the_core():
    code = (
        "import importlib, json, sys\n"
        f"for name in {CORE!r}: importlib.import_module(name)\n"
        "print(json.dumps(sorted(sys.modules)))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, check=True)
    loaded = json.loads(proc.stdout)
    leaked = [m for m in loaded if any(m == f or m.startswith(f + ".") for f in FORBIDDEN)]
    assert leaked == []
