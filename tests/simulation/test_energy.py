"""The energy check of a description (docs/SYSTEMS.md Sec. 4): a flight with zero inputs keeps
the energy the description declares, and a wrong force term is caught."""

from __future__ import annotations

import pytest

from biped_opt.cli.main import main
from biped_opt.errors import InvalidInputError
from biped_opt.simulation.compiled import compile_system
from biped_opt.simulation.energy import DRIFT_TOLERANCE, energy_drift

#: a point mass on a radial spring in polar coordinates (r, phi): M = diag(m, m r^2), so its
#: forces carry the Coriolis term -2 m r r' phi' (FACTOR); phi is measured from the horizontal
POLAR = '''
import sympy as sp
from biped_opt.systems import System

FACTOR = {factor}

s = System("polar", ["r", "phi"], parameters={{"m": 1.0, "g": 1.0, "k": 20.0, "r0": 1.0}})
r, phi = s.q
dr, dphi = s.dq
m, g, k, r0 = s.p.m, s.p.g, s.p.k, s.p.r0
s.mass_matrix = sp.diag(m, m * r**2)
s.forces = lambda J: [m * r * dphi**2 - m * g * sp.sin(phi) - k * (r - r0),
                      -FACTOR * m * r * dr * dphi - m * g * r * sp.cos(phi)]
s.constraint("floor", r * sp.sin(phi) + 5)
s.maneuver("swing", initial={{r: r0, phi: -sp.pi / 2 + 0.8 + s.s}}, terminal=phi + sp.pi / 2,
           outcome=dphi, s_range=(-0.1, 0.1))
{energy}
SYSTEM = s
'''
ENERGY = ("s.energy = (m * (dr**2 + r**2 * dphi**2) / 2 + m * g * r * sp.sin(phi)"
          " + k * (r - r0)**2 / 2)")


def _file(tmp_path, factor=2, energy=ENERGY, name="polar.py"):
    path = tmp_path / name
    path.write_text(POLAR.format(factor=factor, energy=energy))
    return str(path)


@pytest.mark.parametrize("system", ["rocking_bar", "biped"])
def test_the_library_keeps_its_energy(system):
    """Every maneuver's first segment, inputs at zero: the biped's liftoff pushes off on its
    springs in double stance (contact forces do no work), the falls are free."""
    compiled = compile_system(system)
    for maneuver in compiled.maneuvers:
        report = energy_drift(compiled, maneuver)
        assert report.ok and report.relative < DRIFT_TOLERANCE, report
        assert report.samples >= 50 and report.t_end > 0.1


def test_a_wrong_coriolis_term_is_caught(tmp_path, capsys):
    """The right force keeps the energy to ~1e-11 of its scale (measured 1.5e-11: the
    integrator's rtol 1e-10); half the Coriolis term drifts by 1.5e-2. The command says which
    and fails."""
    right = energy_drift(compile_system(_file(tmp_path)))
    assert right.ok and right.relative < 1e-9
    wrong = energy_drift(compile_system(_file(tmp_path, factor=1, name="wrong.py")))
    assert not wrong.ok and wrong.relative > 1e-3
    assert wrong.energy == pytest.approx(right.energy, abs=1e-15)  # (same start, same E(0))
    assert main(["systems", "--check", str(tmp_path / "polar.py")]) == 0
    assert main(["systems", "--check", str(tmp_path / "wrong.py")]) == 1
    out = capsys.readouterr().out
    assert "swing at s =" in out and out.count(": ok") == 1
    assert "FAILED, a force does not match the energy" in out


def test_no_energy_is_reported_not_failed(tmp_path, capsys):
    path = _file(tmp_path, energy="")
    with pytest.raises(InvalidInputError, match="declares no energy"):
        energy_drift(compile_system(path))
    assert main(["systems", "--check", path]) == 0
    assert "not checked: declares no energy" in capsys.readouterr().out


def test_the_energy_uses_states_and_parameters_only(tmp_path):
    path = _file(tmp_path, energy="s.energy = s.s * r", name="bad.py")
    with pytest.raises(InvalidInputError, match="coordinates, velocities and parameters only"):
        energy_drift(compile_system(path))
