"""The processes the package starts import nothing from where they were started, and a
background build runs niced and ends itself after its time (biped_opt.children)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from biped_opt import children

ROOT = Path(__file__).resolve().parents[1]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT)}


def test_a_module_planted_where_the_parent_runs_is_not_imported(tmp_path, monkeypatch):
    """A ``json.py`` in the working directory of the process that starts a child (a download
    folder, a shared /tmp) would run in ``python -m ...``: not in a child of this package."""
    marker = tmp_path / "ran"
    (tmp_path / "json.py").write_text(f"open({str(marker)!r}, 'w').write('planted')\n")
    monkeypatch.chdir(tmp_path)
    child = children.popen("json.tool", stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, env=_env())
    out, err = child.communicate('{"a": 1}', timeout=60)
    assert child.returncode == 0, err
    assert json.loads(out) == {"a": 1}
    assert not marker.exists()


def test_a_child_runs_in_a_private_directory_without_the_unsafe_path(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    child = children.popen("tests.children_probe", stdout=subprocess.PIPE, text=True,
                           env=_env())
    seen = json.loads(child.communicate(timeout=60)[0])
    private = children.private_directory()
    assert seen["cwd"] == private and seen["cwd"] != str(tmp_path)
    assert os.stat(private).st_mode & 0o077 == 0  # (this user's alone)
    assert seen["path0"] != str(tmp_path)
    if sys.version_info >= (3, 11):
        assert seen["safe_path"]


def test_a_background_build_is_niced_listed_and_ends_after_its_time(monkeypatch):
    monkeypatch.setattr(children, "BACKGROUND_LIMIT_S", 1.0)
    start = time.monotonic()
    child = children.popen("tests.children_probe", "wait", background="a test build",
                           stdout=subprocess.PIPE, text=True, env=_env())
    assert "a test build" in children.running_in_background()
    assert "a test build" not in children.running_in_background(children.background_mark())
    seen = json.loads(child.stdout.readline())
    assert seen["nice"] == os.nice(0) + children.BACKGROUND_NICE or seen["nice"] == 19
    assert child.wait(30) == 4  # (ended by its limit, not after its 60 s sleep)
    assert time.monotonic() - start < 20
    assert "a test build" not in children.running_in_background()
    child.stdout.close()


def test_a_command_says_in_one_line_what_it_leaves_running(monkeypatch, capsys):
    """A command that leaves background builds running (niced, limited in time: above) ends
    with one line on stderr naming them; its output and status are untouched."""
    from biped_opt.cli.main import main

    monkeypatch.setattr(children, "running_in_background",
                        lambda since: ["the compile of hop_1",
                                       "the ahead-of-time kernel of hop_1"])
    assert main(["systems", "rocking_bar", "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)[0]["name"] == "rocking_bar"
    assert err == ("note: 2 background builds for later runs still going at low priority, "
                   "ending within 15 min: the compile of hop_1; the ahead-of-time kernel of "
                   "hop_1\n")


def test_a_background_build_outlives_the_directory_it_started_in(tmp_path):
    # a build started by a short command runs on after it, in a directory the command removes
    # when it exits; a compiler that looks up its working directory then failed (every build
    # started from a cached start did)
    code = textwrap.dedent("""
        import os, shutil, tempfile
        gone = tempfile.mkdtemp()
        os.chdir(gone)
        shutil.rmtree(gone)
        from biped_opt import children
        children.limit_background()
        print(os.path.isdir(os.getcwd()))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120, cwd=tmp_path).stdout.strip()
    assert out == "True"
