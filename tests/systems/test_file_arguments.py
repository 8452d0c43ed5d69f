"""System files with arguments and helper modules (docs/SYSTEMS.md Sec. 4, issue 25 part 4).

A ball file whose factory takes the drop height and whose restitution comes from a helper module
beside it. End to end: the compiled system's apex after the first bounce against the closed form
gamma^2 (h + s) (a free fall from rest at h + s, an impact that keeps gamma of the speed, a rise
to gamma^2 of the height), to 1e-9: the event and apex are located to ~1e-12, and DOP853 is exact
to rounding on a parabola.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from biped_opt.errors import InvalidInputError
from biped_opt.simulation.compiled import CompiledSystem
from biped_opt.system_spec import parse_file_spec
from biped_opt.systems.description import SystemDescriptionError
from biped_opt.systems.files import load_system

BALL = textwrap.dedent('''
    import sympy as sp
    from biped_opt.systems import System
    from restitution import GAMMA

    def make_system(height=1.0, name="ball"):
        s = System(name, ["z"], parameters={"g": 1.0, "h0": height, "gamma": GAMMA})
        (z,), (dz,) = s.q, s.dq
        s.mass_matrix = sp.Matrix([[1]])
        s.forces = [-s.p.g]
        s.restitution = s.p.gamma
        s.constraint("floor", z, at=(0, 0, z))
        s.maneuver("bounce", initial={z: s.p.h0 + s.s}, terminal=dz, outcome=z,
                   armed_after="touchdown", final_mode=(), s_range=(-0.5, 0.5))
        return s
''')


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """One cache for the module's tests: the ball's kernel is compiled once (the module's text
    is the same in every test's folder)."""
    return tmp_path_factory.mktemp("cache")


@pytest.fixture
def ball(tmp_path, monkeypatch, cache):
    monkeypatch.setenv("BIPED_OPT_CACHE", str(cache))
    (tmp_path / "ball.py").write_text(BALL)
    (tmp_path / "restitution.py").write_text("GAMMA = 0.5\n")
    return tmp_path / "ball.py"


def test_the_spec_grammar():
    spec = parse_file_spec("sys/chain.py:links=5,feet=true,scale=0.5,kind=knee-2")
    assert str(spec.path) == "sys/chain.py"
    assert spec.arguments == (("links", 5), ("feet", True), ("scale", 0.5), ("kind", "knee-2"))
    assert spec.key() == parse_file_spec("sys/chain.py:scale=0.5,kind=knee-2,feet=true,"
                                         "links=5").key()
    assert parse_file_spec("chain.py").arguments == ()
    assert parse_file_spec("walker3") is None
    for bad, says in (("c.py:links", "name=value"), ("c.py:1x=2", "name=value"),
                      ("c.py:a=1,a=2", "given twice"), ("c.py:a=nan", "must be finite"),
                      ("c.py:a=x y", "not a number"), ("c.py:" + ",".join(
                          f"a{k}=1" for k in range(33)), "more than 32")):
        with pytest.raises(InvalidInputError, match=says):
            parse_file_spec(bad)


def test_arguments_reach_the_factory_and_a_wrong_one_is_named(ball):
    system = load_system(f"{ball}:height=2.5,name=high")
    assert system.name == "high" and system.defaults["h0"] == 2.5
    assert system.defaults["gamma"] == 0.5  # from the helper module beside the file
    assert [p.name for p in system.reads] == ["ball.py", "restitution.py"]
    assert load_system(str(ball)).defaults["h0"] == 1.0  # no arguments: the defaults
    with pytest.raises(SystemDescriptionError, match="make_system: .*unexpected keyword.*mass"):
        load_system(f"{ball}:mass=2")
    plain = ball.parent / "plain.py"
    plain.write_text(BALL.replace("def make_system(", "def build(") + "SYSTEM = build()\n")
    with pytest.raises(SystemDescriptionError, match="takes no arguments"):
        load_system(f"{plain}:height=2")


def test_the_parameterised_ball_bounces_as_the_closed_form_says(ball):
    for height in (1.0, 2.5):
        compiled = CompiledSystem(f"{ball}:height={height}")
        for s in (-0.3, 0.0, 0.2):
            tr = compiled.simulate("bounce", s)
            assert tr.success
            assert tr.outcome == pytest.approx(0.25 * (height + s), abs=1e-9)


def test_editing_the_helper_module_misses_the_start_index(ball):
    spec = f"{ball}:height=2"
    assert CompiledSystem(spec).parameters["gamma"] == 0.5
    (ball.parent / "restitution.py").write_text("GAMMA = 0.8\n")
    compiled = CompiledSystem(spec)
    assert compiled.parameters["gamma"] == 0.8
    # 0.8^2 (2 + 0.1): the kernel is the same (gamma is a parameter), its defaults are new
    assert compiled.simulate("bounce", 0.1).outcome == pytest.approx(0.64 * 2.1, abs=1e-9)
    # a new process reads the index, not the file: it sees the edit too
    (ball.parent / "restitution.py").write_text("GAMMA = 0.6\n")
    code = ("import sys; from biped_opt.simulation.compiled import CompiledSystem; "
            "print(CompiledSystem(sys.argv[1]).parameters['gamma'])")
    out = subprocess.run([sys.executable, "-c", code, spec], capture_output=True, text=True,
                         check=True, timeout=300)
    assert out.stdout.strip() == "0.6"


def test_a_deleted_scene_module_is_made_again(ball, cache):
    # the start index names the scene's module beside the simulator's; with that file gone a
    # new process derives the description again instead of failing when it draws
    spec = f"{ball}:height=2"
    compiled = CompiledSystem(spec)
    assert compiled.scene.contact_names == ("floor",)
    scenes = list((cache / "systems").glob("ball_scene_*.py"))
    assert len(scenes) == 1
    scenes[0].unlink()
    code = ("import sys; from biped_opt.simulation.compiled import CompiledSystem; "
            "print(CompiledSystem(sys.argv[1]).scene.contact_names)")
    out = subprocess.run([sys.executable, "-c", code, spec], capture_output=True, text=True,
                         check=True, timeout=300)
    assert out.stdout.strip() == "('floor',)"
    assert scenes[0].is_file()
