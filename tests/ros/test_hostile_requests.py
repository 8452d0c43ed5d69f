"""The hostile mode of ``bench/request_fuzz.py`` builds what it claims: each case a request that
goes on the wire as it is, every file it names planted where the name leads from the nodes'
working directory, each file's code creating the marker the count looks for, and the grid the
size it says (built small here; the bench sends the full sizes to a node)."""

from __future__ import annotations

import json
import math
import runpy

import pytest

from bench.request_fuzz import (
    BASE_STUDY,
    bound_cases,
    code_cases,
    grid_study,
    heavy_requests,
    plant_files,
)
from biped_opt import ros
from biped_opt.studies.study import Study

pytestmark = pytest.mark.skipif(ros.BACKEND != "dds", reason="the built-in backend's wire types")

SERVICES = {"policy": ros.srvs.OptimalPolicy, "point": ros.srvs.StudyPoint}


def _named_path(case, root):
    """The file a case names, resolved as a node in root/cwd would (trailing space kept out)."""
    if case.kind == "policy":
        text = case.message.system or case.message.problem
    else:
        spec = json.loads(case.message.study)
        text = spec.get("problem") or spec["system"]
    return (root / "cwd" / text.rstrip()).resolve(), text


def test_code_cases_name_planted_files_whose_code_writes_the_marker(tmp_path):
    cases = code_cases(tmp_path)
    kinds = {c.kind for c in cases}
    assert kinds == {"policy", "point", "goal"}
    markers = [c.marker for c in cases if c.marker is not None]
    # 6 variants for each of the three kinds, each its own marker (a hit names its case)
    assert len(markers) == 18 and len(set(markers)) == 18
    assert not any(m.exists() for m in markers)
    for case in cases:
        if case.marker is None:
            continue
        path, text = _named_path(case, tmp_path)
        assert path.is_file(), case.name
        if case.name.endswith("trailing_space"):
            assert text.endswith(" ") and not (tmp_path / "cwd" / text).exists()
        if case.name.endswith(("_relative", "_parent")):
            assert not text.startswith("/")
        if case.name.endswith("_parent"):
            assert text.startswith("../")
    # running a planted file (what a vulnerable node does) creates exactly its marker
    policy_abs = next(c for c in cases if c.name == "policy_absolute")
    runpy.run_path(str(_named_path(policy_abs, tmp_path)[0]))
    assert [m for m in markers if m.exists()] == [policy_abs.marker]


def test_yaml_problem_names_a_planted_system(tmp_path):
    files = plant_files(tmp_path, "x")
    yaml_path, marker = files["problem_yaml"]
    text = (tmp_path / "x_problem.yaml").read_text()
    assert yaml_path.endswith("x_problem.yaml") and "system: x_yaml_system.py" in text
    runpy.run_path(str(tmp_path / "x_yaml_system.py"))
    assert marker.exists()


def test_requests_serialize_to_raw_wire_bytes(tmp_path):
    cases = code_cases(tmp_path) + bound_cases(tmp_path, name_bytes=64, grid_values=3)
    for case in cases:
        if case.kind == "goal":
            json.loads(case.message.study)  # the goal's study is JSON a coordinator parses
            continue
        srv = SERVICES[case.kind]
        # the sample a client writes for the request (what the hostile mode's clients send)
        sample = srv.RequestWire(body=case.message)
        sample.header.guid, sample.header.seq = 7, 3
        raw = sample.serialize()
        # XCDR1 little endian, then the rmw_cyclonedds header {guid, seq}
        assert raw[:2] == b"\x00\x01"
        back = srv.RequestWire.deserialize(raw)
        assert (back.header.guid, back.header.seq) == (7, 3)
        assert back.body == case.message, case.name


def test_bound_cases_have_the_sizes_they_claim(tmp_path):
    cases = {c.name: c for c in bound_cases(tmp_path, name_bytes=100, grid_values=3)}
    assert len(cases["policy_long_system_name"].message.system) == 100
    assert len(json.loads(cases["point_long_system_name"].message.study)["system"]) == 100
    full = {c.name: c for c in bound_cases(tmp_path, grid_values=3)}
    path = full["policy_long_system_path"].message.system
    assert 8000 <= len(path) <= 8192 and path.startswith("/") and path.endswith(".py")
    assert json.loads(full["point_long_system_path"].message.study)["system"] == path
    spec = json.loads(cases["point_huge_grid"].message.study)
    study = Study.from_spec(spec, where="study")
    assert len(study.points()) == 3**4  # small here; the bench's 400 gives 400**4
    full = json.loads(grid_study())
    assert math.prod(len(v) for v in full["grid"].values()) == 400**4
    assert {k: v for k, v in full.items() if k != "grid"} == \
        {k: v for k, v in BASE_STUDY.items() if k != "grid"}


def test_heavy_requests_name_a_library_walker():
    from biped_opt.systems.files import WALKER

    requests = heavy_requests()
    assert len(requests) == 5 and all(WALKER.match(r.system) for r in requests)
