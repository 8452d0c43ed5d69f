"""Two processes compiling the same new system at once (as two test workers, or two nodes, do on
a fresh checkout) both get a working module, and leave a cache a third process starts from
without compiling anything."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from biped_opt.simulation.compiled import CompiledSystem

ROOT = Path(__file__).resolve().parents[2]

# Each of the two runs this in a fresh interpreter on an empty cache. The write of the generated
# module waits until the other process has come as far (both have found the file missing and
# rendered it: the race at its worst). Then "a" writes and imports the module at once, "b" writes
# it again only once "a" has imported it (as when "b" is descheduled between its check and its
# write), and "a" simulates only after "b" has, so "a" must load the functions "b" compiled into
# the disk cache although the file was replaced under it (all but the step, which each compiles
# first while building; Numba stamps its cache with a hash of the module file's content; an older
# Numba stamped it with the modification time, which the second write changes).
_COMPILE = """
import json, sys, time
from pathlib import Path
from biped_opt.simulation import compiled

barrier, me = Path(sys.argv[1]), sys.argv[2]
write, load = compiled.write_whole, compiled._import

def wait_for(*names):
    deadline = time.monotonic() + 300
    while not all((barrier / n).exists() for n in names) and time.monotonic() < deadline:
        time.sleep(0.005)

def write_together(path, text, **kw):
    if path.suffix == ".py":  # (the module, not the index entry)
        (barrier / f"arrived_{me}").touch()
        wait_for("arrived_a", "arrived_b", *(["imported_a"] if me == "b" else []))
    return write(path, text, **kw)

def import_and_say(name, path):
    module = load(name, path)
    (barrier / f"imported_{me}").touch()
    return module

compiled.write_whole, compiled._import = write_together, import_and_say
c = compiled.CompiledSystem("rocking_bar")
if me == "a":
    wait_for("done_b")
tr = c.simulate("drop", 0.1)
(barrier / f"done_{me}").touch()
made = c.module._CFUNCS  # (the system's compiled functions, by name)
print(json.dumps({"success": tr.success, "outcome": tr.outcome,
                  "met": sorted(p.name for p in barrier.iterdir()),
                  "compiled": sorted(k for k, f in made.items() if f.cache_hits == 0),
                  "loaded": sorted(k for k, f in made.items() if f.cache_hits)}))
"""

# A third process, after both: the kernel's machine code comes from the disk cache.
_LOAD = """
import json
from biped_opt.simulation import compiled
c = compiled.CompiledSystem("rocking_bar")
tr = c.simulate("drop", 0.1)
made = c.module._CFUNCS.values()
print(json.dumps({"success": tr.success, "outcome": tr.outcome,
                  "loaded": sum(f.cache_hits > 0 for f in made),
                  "compiled": sum(f.cache_hits == 0 for f in made)}))
"""


def _env(cache: Path) -> dict[str, str]:
    path = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    return dict(os.environ, PYTHONPATH=path, BIPED_OPT_CACHE=str(cache))


def _report(proc: subprocess.Popen) -> dict:
    out, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err
    return json.loads(out.strip().splitlines()[-1])


def test_two_processes_compile_the_same_new_system_at_once(tmp_path):
    cache, barrier = tmp_path / "cache", tmp_path / "barrier"
    barrier.mkdir()
    procs = [subprocess.Popen([sys.executable, "-c", _COMPILE, str(barrier), me],
                              env=_env(cache), cwd=tmp_path, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for me in ("a", "b")]
    try:
        reports = [_report(p) for p in procs]
    finally:
        for p in procs:
            p.kill()
    # the same generated code on the same input as this process's (warm) copy: the same
    # floating-point operations, so the outcomes agree to rounding
    ref = CompiledSystem("rocking_bar").simulate("drop", 0.1)
    assert ref.success
    for report in reports:
        # both reached the write before either wrote: the race did happen
        assert report["met"][:2] == ["arrived_a", "arrived_b"]
        assert report["success"]
        assert report["outcome"] == pytest.approx(ref.outcome, rel=1e-12, abs=1e-14)
    a, b = reports
    # both compiled the step while building (each compiles it first, at the same time here);
    # "a" then waited for "b" to simulate, and loaded all the rest from the cache "b" (and the
    # second processes) filled
    assert a["compiled"] == ["step"] and len(a["loaded"]) == 9, (a, b)
    assert "step" in b["compiled"] and len(b["compiled"]) + len(b["loaded"]) == 10, b
    files = sorted(p.name for p in (cache / "systems").iterdir() if p.is_file())
    # one simulator module and one scene module, no temporary file left behind
    assert len(files) == 2 and files[0].startswith("rocking_bar_") \
        and files[1].startswith("rocking_bar_scene_"), files
    load = _report(subprocess.Popen([sys.executable, "-c", _LOAD], env=_env(cache),
                                    cwd=tmp_path, stdout=subprocess.PIPE,
                                    stderr=subprocess.PIPE, text=True))
    assert load["success"]
    assert load["outcome"] == pytest.approx(ref.outcome, rel=1e-12, abs=1e-14)
    # loaded, not compiled: the cache both processes filled is the one the file on disk names
    assert load["loaded"] == 10 and load["compiled"] == 0, load
