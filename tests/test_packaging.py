"""The ament_python packaging a ROS 2 user relies on (ROS.md Sec. 4, issue 6 item 4).

Always run: setup.py's ``data_files`` and console scripts, package.xml and setup.cfg, read
without any ROS tool. Run only when ``colcon`` is on PATH (deselect with ``-m "not colcon"``):
a real ``colcon build --packages-select biped_opt`` of a copy of the tree in a temporary
directory, then the install layout ``ros2 run`` / ``ros2 launch`` expect, the installed package
imported from ``install/`` and a node started from its installed script.
"""

from __future__ import annotations

import configparser
import importlib
import os
import runpy
import shutil
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import setuptools

ROOT = Path(__file__).resolve().parents[1]
PKG = "biped_opt"
NODES = ("simulator", "optimiser", "recorder")

#: requirements.txt names with a well-known rosdep key a ROS user installs with apt
ROSDEP_KEYS = {
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "pyyaml": "python3-yaml",
    "matplotlib": "python3-matplotlib",
    "sympy": "python3-sympy",
    "pytest": "python3-pytest",
}


@pytest.fixture(scope="module")
def setup_kwargs() -> dict:
    """The keyword arguments setup.py passes to setuptools.setup (nothing is built)."""
    captured: dict = {}
    original, cwd = setuptools.setup, Path.cwd()
    setuptools.setup = lambda **kw: captured.update(kw)
    try:
        os.chdir(ROOT)  # data_files globs are relative to the package root, as under colcon/pip
        runpy.run_path(str(ROOT / "setup.py"), run_name="__main__")
    finally:
        setuptools.setup = original
        os.chdir(cwd)
    return captured


def _requirement_names(filename: str) -> set[str]:
    names = set()
    for line in (ROOT / filename).read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            names.add(line.split("==")[0].split(">=")[0].strip().lower())
    return names


def _package_xml(path: Path = ROOT / "package.xml") -> ET.Element:
    return ET.parse(path).getroot()


# ------------------------------------------------------------------------------------------------
# setup.py


def test_data_files_exist_and_cover_the_share_directory(setup_kwargs):
    installed: dict[str, str] = {}  # source file (relative to root) -> install directory
    for target, sources in setup_kwargs["data_files"]:
        assert sources, f"data_files entry {target!r} is empty (a glob matched nothing)"
        for src in sources:
            assert (ROOT / src).is_file(), src
            installed[Path(src).as_posix()] = target
    assert installed[f"resource/{PKG}"] == "share/ament_index/resource_index/packages"
    assert (ROOT / "resource" / PKG).is_file()
    assert installed["package.xml"] == f"share/{PKG}"
    expected = [p for p in (ROOT / "launch").glob("*.py") if not p.name.startswith("_")]
    for pattern in ("*.yaml", "*.rviz", "*.json"):  # parameters, RViz2 view, Foxglove layout
        expected += list((ROOT / "config").glob(pattern))
    assert (ROOT / "config" / "biped_opt.rviz").is_file()
    assert expected, "no launch files or config YAML found"
    for path in expected:
        rel = path.relative_to(ROOT).as_posix()
        assert installed.get(rel) == f"share/{PKG}/{path.parent.name}", rel
    # every interface file keeps its place relative to msg_defs/, under share/biped_opt/msg_defs
    defs = [p for p in (ROOT / "msg_defs").rglob("*") if p.is_file()]
    assert any(p.suffix == ".msg" for p in defs) and any(p.suffix == ".srv" for p in defs)
    for path in defs:
        rel = path.relative_to(ROOT).as_posix()
        assert installed.get(rel) == f"share/{PKG}/{Path(rel).parent.as_posix()}", rel


def test_console_scripts_name_existing_main_functions(setup_kwargs):
    scripts = {}
    for entry in setup_kwargs["entry_points"]["console_scripts"]:
        name, target = (part.strip() for part in entry.split("="))
        scripts[name] = target
    for node in NODES:
        assert scripts[node] == f"{PKG}.nodes.{node}:main"
    for name, target in scripts.items():
        module, func = target.split(":")
        assert callable(getattr(importlib.import_module(module), func)), name


def test_setup_metadata_matches_package_xml(setup_kwargs):
    xml = _package_xml()
    assert setup_kwargs["name"] == PKG
    assert setup_kwargs["version"] == xml.findtext("version")
    assert PKG in setup_kwargs["packages"] and f"{PKG}.nodes" in setup_kwargs["packages"]
    assert not any(p.startswith("tests") for p in setup_kwargs["packages"])


# ------------------------------------------------------------------------------------------------
# package.xml and setup.cfg


def test_package_xml_is_format3_ament_python():
    xml = _package_xml()
    assert xml.tag == "package" and xml.get("format") == "3"
    assert xml.findtext("name") == PKG
    assert xml.findtext("export/build_type") == "ament_python"
    for tag in ("version", "description", "maintainer", "license"):
        assert (xml.findtext(tag) or "").strip(), tag
    assert xml.find("maintainer").get("email")


def test_package_xml_dependencies_agree_with_requirements():
    xml = _package_xml()
    exec_deps = {e.text.strip() for e in xml.iter() if e.tag in ("exec_depend", "depend")}
    test_deps = {e.text.strip() for e in xml.iter() if e.tag in ("test_depend", "depend")}
    runtime = _requirement_names("requirements.txt")
    dev = _requirement_names("requirements-dev.txt")
    for name, key in ROSDEP_KEYS.items():
        if name in runtime:
            assert key in exec_deps, f"{name} is in requirements.txt but {key} is no exec_depend"
        elif name in dev:
            assert key in test_deps, f"{name} is in requirements-dev.txt but {key} no test_depend"
    # no stale rosdep key: each python3-* dependency names something the pins install
    known = {key: name for name, key in ROSDEP_KEYS.items()}
    for key in exec_deps | test_deps:
        if key.startswith("python3-"):
            assert known.get(key) in runtime | dev, f"{key} matches no pinned requirement"
    # the launch file's imports and the rclpy backend's interfaces
    launch_imports = (ROOT / "launch" / "biped_launch.py").read_text()
    for dep in ("launch", "launch_ros", "ament_index_python"):
        if f"import {dep}" in launch_imports or f"from {dep}" in launch_imports:
            assert dep in exec_deps, dep
    interfaces = _package_xml(ROOT / "msg_defs" / "package.xml").findtext("name")
    assert interfaces in exec_deps


def test_setup_cfg_installs_scripts_where_ros2_run_looks():
    cfg = configparser.ConfigParser(interpolation=None)
    cfg.read(ROOT / "setup.cfg")
    assert cfg["develop"]["script_dir"] == f"$base/lib/{PKG}"
    assert cfg["install"]["install_scripts"] == f"$base/lib/{PKG}"


# ------------------------------------------------------------------------------------------------
# colcon (optional: only where Debian's or ROS's colcon is installed)

_COPY_IGNORE = shutil.ignore_patterns(
    ".git", ".venv", "venv", "build", "install", "log", "out", "__pycache__", "*.egg-info",
    ".pytest_cache", ".ruff_cache", ".mypy_cache", "*.nbi", "*.nbc",
)


@pytest.fixture(scope="module")
def colcon_install(tmp_path_factory) -> Path:
    """``colcon build --packages-select biped_opt`` of a copy of the tree; returns the prefix."""
    colcon = shutil.which("colcon")
    if colcon is None:
        pytest.skip("colcon is not on PATH (apt-get install colcon, or a ROS 2 installation)")
    ws = tmp_path_factory.mktemp("colcon_ws")
    src = ws / "src"
    shutil.copytree(ROOT, src, ignore=_COPY_IGNORE)
    # colcon must run on its own interpreter, not on this test's virtual environment
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    proc = subprocess.run(
        [colcon, "--log-base", str(ws / "log"), "build", "--base-paths", str(src),
         "--build-base", str(ws / "build"), "--install-base", str(ws / "install"),
         "--packages-select", PKG],
        cwd=ws, env=env, capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return ws / "install" / PKG


def _installed_env(prefix: Path) -> dict[str, str]:
    """What ``source install/setup.sh`` sets for this package, on top of this environment."""
    site = prefix / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}"
    env = dict(os.environ)
    env["PYTHONPATH"] = str(site / "site-packages")
    env["AMENT_PREFIX_PATH"] = str(prefix)
    env["PYTHONUNBUFFERED"] = "1"
    return env


@pytest.mark.colcon
def test_colcon_install_layout(colcon_install):
    prefix = colcon_install
    for node in NODES:
        script = prefix / "lib" / PKG / node
        assert script.is_file() and os.access(script, os.X_OK), script
        shebang = script.read_text().splitlines()[0]
        assert shebang.startswith("#!") and "python3" in shebang, shebang
    marker = prefix / "share" / "ament_index" / "resource_index" / "packages" / PKG
    assert marker.is_file()
    share = prefix / "share" / PKG
    for rel in ("package.xml", "launch/biped_launch.py", "config/biped.yaml",
                "config/biped_opt.rviz", "config/foxglove_layout.json",
                "msg_defs/package.xml", "msg_defs/CMakeLists.txt"):
        assert (share / rel).is_file(), rel
    for path in (ROOT / "msg_defs").rglob("*.*"):
        assert (share / path.relative_to(ROOT)).is_file(), path


@pytest.mark.colcon
def test_colcon_installed_package_imports_from_install(colcon_install, tmp_path):
    site = colcon_install / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}"
    probe = (
        "import biped_opt, biped_opt.nodes.optimiser as o, importlib.metadata as m\n"
        "from biped_opt.interface_defs import find_msg_defs\n"
        "print(biped_opt.__file__); print(find_msg_defs())\n"
        "print(m.entry_points(group='console_scripts')['optimiser'].value)\n"
    )
    # cwd outside the source tree so the checkout cannot shadow the installed copy
    out = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, capture_output=True,
                         text=True, env=_installed_env(colcon_install), timeout=60, check=True)
    module, defs, entry = out.stdout.splitlines()
    assert Path(module).is_relative_to(site)
    assert Path(defs) == colcon_install / "share" / PKG / "msg_defs"
    assert entry == f"{PKG}.nodes.optimiser:main"


@pytest.mark.colcon
def test_colcon_installed_node_starts_and_stops_on_sigint(colcon_install, tmp_path, domain_id):
    """The installed script, run the way ``ros2 run --prefix <python>`` runs it, serves."""
    from biped_opt import ros

    env = _installed_env(colcon_install)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env["BIPED_OPT_BACKEND"] = "dds"
    script = colcon_install / "lib" / PKG / "optimiser"
    # a fresh install has no compiled kernels: not warming them up keeps this a packaging test
    # (the warm-up itself is tested in tests/hybrid and by every Graph in tests/nodes)
    proc = subprocess.Popen([sys.executable, str(script), "--ros-args", "-p", "warm_up:=false"],
                            cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ctx = ros.Context()
        ros.init(args=[], context=ctx, domain_id=domain_id)
        node = ros.Node("packaging_probe", context=ctx)
        client = node.create_client(ros.srvs.OptimalPolicy, "/biped/optimal_policy")
        start = time.monotonic()
        found = client.wait_for_service(timeout_sec=45.0)
        node.destroy_node()
        ros.try_shutdown(context=ctx)
        assert found, f"service not up after {time.monotonic() - start:.1f} s"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "Traceback" not in err
