"""The optimiser serving optimal-control problems on other systems than the biped (rocking bar,
3-leg walker) through the in-process graph on real DDS, and optimal sweeps of those systems
recorded to MCAP and read back by mcap-ros2-support."""

from __future__ import annotations

import math
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from biped_opt import ros
from biped_opt.control.problems import get_problem
from biped_opt.control.solve import optimal_policy
from biped_opt.control.theorem1 import value_slopes
from biped_opt.errors import BipedOptError
from biped_opt.nodes.compiler import BUSY
from biped_opt.nodes.graph import Graph
from biped_opt.nodes.recorder import SweepRequest
from biped_opt.paper.problems import get_problem as biped_problem
from biped_opt.paper.solve import optimal_policy as biped_optimal_policy
from biped_opt.piecewise import theta_grid
from biped_opt.record.report import load_sweep
from biped_opt.simulation.compiled import CompiledSystem
from tests.conftest import unique_domain_id

from .test_nodes import call

#: the node runs the same solver on the same problem and s in the same process, and the reply
#: carries float64: the numbers agree to the last bit; 1e-12 allows for nothing but that
TOL = 1e-12

#: (system, problem = maneuver, s values): the bar's drop at s = 0.1 lands on one end, the
#: walker's touchdown at s = 0.1 visits masks 0, 1, 3, 7 with u1 on its upper bound, at -0.05
#: it lands foot 3 first
CASES = {
    "rocking_bar": ("drop", (0.1, -0.07)),
    "walker3_coupled": ("touchdown", (0.1, -0.05)),
}


#: a problem file on the bar's maneuver, served by name from the optimiser's system_paths
OTHER = "system: rocking_bar\nmaneuver: drop\ndecisions: {u_th: [-0.5, 0.5]}\n"
#: a robot's URDF, served by its stem from the optimiser's system_paths
HOPPER = Path(__file__).resolve().parents[1] / "systems" / "urdf" / "hopper.urdf"


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    """One graph for the module: its optimiser compiles both systems at start-up (parameter
    systems) and serves problem files by name from a directory (system_paths), its simulator
    and recorder serve the rocking bar."""
    problems = tmp_path_factory.mktemp("problems")
    (problems / "other.yaml").write_text(OTHER)
    shutil.copy(HOPPER, problems / "hopper.urdf")
    g = Graph(domain_id=unique_domain_id(), overrides={
        "simulator": {"autostart": False, "system": "rocking_bar"},
        "optimiser": {"systems": sorted(CASES), "system_paths": [str(problems)]},
        "recorder": {"system": "rocking_bar"}})
    probe = ros.Node("probe", context=g.context)
    g.executor.add_node(probe)
    g.probe = probe
    g.problems = problems
    yield g
    g.executor.remove_node(probe)
    probe.destroy_node()
    g.close()


def _policy(probe, **fields):
    return call(probe, ros.srvs.OptimalPolicy, "/biped/optimal_policy", **fields)


def _policy_when_compiled(probe, timeout: float = 240.0, **fields):
    """The reply once the node has compiled what the request needs (it answers ``busy`` while
    it compiles: tests/nodes/test_hostile.py checks that)."""
    deadline = time.monotonic() + timeout
    reply = _policy(probe, **fields)
    while reply.message.startswith(BUSY) and time.monotonic() < deadline:
        time.sleep(0.5)
        reply = _policy(probe, **fields)
    return reply


@pytest.mark.parametrize("name", sorted(CASES))
def test_replies_equal_the_core(graph, name):
    maneuver, values = CASES[name]
    problem = get_problem(name, maneuver)
    for s in values:
        # problem "" = the problem named like the maneuver; both spellings are one problem
        for given in ("", maneuver):
            reply = _policy(graph.probe, maneuver=maneuver, theta0=s, system=name,
                            problem=given)
            core = optimal_policy(problem, s)
            assert reply.success and core.success, reply.message
            assert reply.message == core.message
            assert list(reply.decision_names) == list(problem.decision_names)
            np.testing.assert_allclose(reply.policy, core.x, rtol=0, atol=TOL)
            np.testing.assert_allclose(reply.system_inputs, core.inputs, rtol=0, atol=TOL)
            assert abs(reply.value - core.value) <= TOL
            assert abs(reply.outcome - core.outcome) <= TOL
            assert abs(reply.t_final - core.t_final) <= TOL
            assert list(reply.contact_modes) == list(core.modes)
            np.testing.assert_allclose(reply.event_times, core.event_times, rtol=0, atol=TOL)
            assert list(reply.mode_sequence) == []  # the biped's ContactMode field
            assert all(math.isnan(v) for v in reply.inputs)  # the biped's [u1, u2, u12]
            np.testing.assert_allclose(reply.value_derivative,
                                       value_slopes(problem, core), rtol=0, atol=TOL)
    if name == "walker3_coupled":  # the walker's modes as masks over foot1..3
        reply = _policy(graph.probe, maneuver=maneuver, theta0=0.1, system=name)
        assert list(reply.contact_modes) == [0, 1, 3, 7]


@pytest.mark.parametrize("name", sorted(CASES))
def test_value_derivative_matches_finite_differences(name):
    """The envelope-theorem dV/ds against central differences of the optimal value (step
    1e-4; the differences agree with those at 1e-3 and 1e-5 to 1e-9 of the slope). The walker's
    agree to ~1e-8 of the slope. The bar's optimum lands its outcome nearly on the target, so its
    slope 2 (outcome - target) d outcome/ds is small (~4e-4) and the solver's policy error
    (~1e-10, the cost's u-gradient at its optimum is ~1e-6) moves dc/ds by c_su du ~ 1e-7:
    tolerance 1e-5 of the slope plus 2e-7. A wrong factor or sign misses by the slope itself."""
    maneuver, values = CASES[name]
    problem = get_problem(name, maneuver)
    h = 1e-4
    for s in values:
        core = optimal_policy(problem, s)
        left, right = value_slopes(problem, core)
        up, down = optimal_policy(problem, s + h), optimal_policy(problem, s - h)
        assert up.branch == down.branch == core.branch  # smooth here: one piece
        fd = (up.value - down.value) / (2 * h)
        assert left == right  # no event changes order within the step: one branch both sides
        assert abs(right - fd) <= 1e-5 * abs(fd) + 2e-7, (right, fd)
        assert abs(fd) > 1e-4  # a slope worth testing


def test_old_biped_requests_get_todays_reply(graph):
    """Empty system and problem: the biped's problems of the node's parameters, as before the
    fields existed (MODEL.md R5: V(0.05) = 0.0194158739483); the new fields describe it too."""
    reply = _policy(graph.probe, maneuver="touchdown", theta0=0.05)
    core = biped_optimal_policy(biped_problem("touchdown"), 0.05)
    assert reply.success, reply.message
    np.testing.assert_array_equal(np.asarray(reply.policy), core.x)
    assert reply.value == core.value and reply.outcome == core.outcome
    assert abs(reply.value - 0.0194158739483) < 1e-8
    assert list(reply.mode_sequence) == [int(m) for m in core.modes]
    assert list(reply.contact_modes) == list(reply.mode_sequence)
    assert list(reply.decision_names) == ["u1", "u2"]
    assert list(reply.system_inputs) == list(reply.inputs) == list(core.inputs)
    same = _policy(graph.probe, maneuver="touchdown", theta0=0.05, system="biped")
    assert same.value == reply.value and list(same.policy) == list(reply.policy)


def test_bad_requests_are_refused_and_the_node_keeps_serving(graph):
    for fields, start in (
        ({"system": "no_such_system", "maneuver": "drop"}, "system: unknown system"),
        ({"system": "missing/bar.py", "maneuver": "drop"},
         "system: 'missing/bar.py' is not a system name"),
        ({"system": "rocking_bar", "maneuver": "drop", "problem": "missing.yaml"},
         "problem: 'missing.yaml' is not a problem name"),
        ({"system": "rocking_bar", "maneuver": "drop", "problem": "far"},
         "problem: "),
        ({"system": "rocking_bar", "maneuver": "hop"}, "maneuver: rocking_bar has no maneuver"),
        ({"system": "walker3_coupled", "maneuver": "liftoff", "problem": "touchdown"},
         "maneuver: problem touchdown is on maneuver 'touchdown', not 'liftoff'"),
        ({"system": "walker3_coupled", "maneuver": "drop", "problem": "other"},
         "problem: other is a problem on rocking_bar, not on walker3_coupled"),
        ({"system": "rocking_bar", "maneuver": "drop", "theta0": math.nan}, "theta0:"),
        ({"system": "rocking_bar", "maneuver": "drop", "theta0": math.inf}, "theta0:"),
    ):
        reply = _policy_when_compiled(graph.probe, **{"theta0": 0.1, **fields})
        assert not reply.success and reply.message.startswith(start), (fields, reply.message)
        assert len(reply.message) < 300
    # a problem file of system_paths by name, with the system left to the file
    good = _policy_when_compiled(graph.probe, maneuver="drop", theta0=0.1, problem="other")
    assert good.success and list(good.decision_names) == ["u_th"]
    good = _policy(graph.probe, maneuver="drop", theta0=0.1, system="rocking_bar")
    assert good.success


def test_a_urdf_of_system_paths_is_served_by_its_stem(graph):
    """``hopper`` names ``hopper.urdf`` of system_paths: the node imports it (in its compile
    process) with the importer's defaults and answers its declared problem ``drop`` (the hips'
    efforts within the URDF's effort limits) as the solver does on the same file in this
    process. A suffix, a path or options are no name."""
    reply = _policy_when_compiled(graph.probe, system="hopper", maneuver="drop", theta0=0.05)
    core = optimal_policy(get_problem(str(graph.problems / "hopper.urdf"), "drop"), 0.05)
    assert reply.success and core.success, reply.message
    assert list(reply.decision_names) == ["left_hip_effort", "right_hip_effort"]
    np.testing.assert_allclose(reply.policy, core.x, rtol=0, atol=TOL)
    assert abs(reply.value - core.value) <= TOL
    assert list(reply.contact_modes) == list(core.modes)
    assert all(-4.0 <= u <= 4.0 for u in reply.policy)  # (the URDF's effort="4")
    for system in ("hopper.urdf", "hopper.urdf:base=fixed", str(graph.problems / "hopper")):
        reply = _policy(graph.probe, system=system, maneuver="drop", theta0=0.05)
        assert not reply.success and "is not a system name" in reply.message, reply.message
    # (a file's maneuver is checked where its description is built: the compile process)
    reply = _policy_when_compiled(graph.probe, system="hopper", maneuver="hop", theta0=0.05)
    assert not reply.success and "hopper has no maneuver 'hop'" in reply.message, reply.message


def test_paths_are_refused_with_the_default_parameters(domain_id, tmp_path):
    """Without system_paths a request names library systems and declared problems only: a
    problem file, by path or by name, is refused; a library system is served."""
    other = tmp_path / "p.yaml"
    other.write_text(OTHER)
    with Graph(domain_id=domain_id, overrides={
            "simulator": {"autostart": False, "warm_up": False},
            "optimiser": {"warm_up": False, "systems": ["rocking_bar"]}}) as g:
        probe = ros.Node("probe", context=g.context)
        g.executor.add_node(probe)
        reply = _policy(probe, maneuver="drop", theta0=0.1, problem=str(other))
        assert not reply.success and reply.message.startswith("problem: '")
        assert "is not a problem name" in reply.message and "never a file" in reply.message
        reply = _policy(probe, maneuver="drop", theta0=0.1, problem="p")
        assert not reply.success and "declares no problem 'p'" in reply.message, reply.message
        assert _policy(probe, maneuver="drop", theta0=0.1, system="rocking_bar").success
        g.executor.remove_node(probe)
        probe.destroy_node()


def test_a_bad_systems_parameter_stops_the_node(domain_id):
    with pytest.raises(BipedOptError, match="^systems: unknown system 'no_such_system'"):
        Graph(domain_id=domain_id, overrides={
            "simulator": {"autostart": False, "warm_up": False},
            "optimiser": {"systems": ["no_such_system"], "warm_up": False}})


def test_optimal_sweep_of_the_bar_recorded_and_read_by_mcap_ros2(graph, tmp_path):
    """An optimal sweep of the rocking bar through optimiser and simulator: mcap-ros2-support
    decodes SweepPoints equal to the core's optimum at each s and SystemStates equal to the
    compiled system's samples at the optimal inputs; the metadata holds the problem."""
    out = tmp_path / "bar_optimal.mcap"
    summary = graph.recorder.record(SweepRequest(
        maneuver="drop", theta0_min=-0.1, theta0_max=0.1, num=5, optimal=True, output=out,
        system="rocking_bar"))
    assert summary.failed == 0 and summary.recorded == 5
    problem = get_problem("rocking_bar", "drop")
    compiled = CompiledSystem("rocking_bar")
    points, states = {}, {}
    with open(out, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _schema, channel, _message, msg in reader.iter_decoded_messages():
            if channel.topic == "/biped/sweep":
                points[msg.theta0] = msg
            elif channel.topic == "/biped/system_state":
                states.setdefault(msg.s, []).append(
                    [msg.t, *msg.q, *msg.qdot, msg.contact_mode, *msg.contact_force])
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert sorted(points) == sorted(states) == list(theta_grid(-0.1, 0.1, 5))
    for s, point in points.items():
        core = optimal_policy(problem, s)
        assert point.optimal
        np.testing.assert_allclose(point.policy, core.x, rtol=0, atol=TOL)
        assert abs(point.value - core.value) <= TOL and abs(point.outcome - core.outcome) <= TOL
        assert list(point.mode_sequence) == list(core.modes)
        tr = compiled.simulate("drop", s, core.inputs, sample_dt=1 / 200)
        np.testing.assert_allclose(np.array(states[s]), tr.samples, rtol=0, atol=TOL)
    sweep = metadata["biped_opt.sweep"]
    assert sweep["optimal"] == "True" and sweep["system"] == "rocking_bar"
    assert sweep["problem"] and '"u_th"' in sweep["problem"]
    recorded = load_sweep(out)
    assert recorded.optimal and recorded.system == "rocking_bar"
    assert list(recorded.policy) == ["u_th"]


def test_recorder_refuses_a_problem_the_system_lacks(graph, tmp_path):
    base = {"maneuver": "drop", "theta0_min": -0.1, "theta0_max": 0.1, "num": 3,
            "optimal": True, "output": tmp_path / "x.mcap", "system": "rocking_bar"}
    for change, start in (({"problem": "far"}, "problem: "),
                          ({"problem": "", "maneuver": "hop"}, "maneuver:")):
        with pytest.raises(BipedOptError) as err:
            graph.recorder.record(SweepRequest(**{**base, **change}))
        assert str(err.value).startswith(start), err.value
    assert not (tmp_path / "x.mcap").exists()
