"""The count of smooth pieces near simultaneous contact (paper Sec. V-B) for n = 1, 2 legs.

The counts are exact integers for a fixed seed; the sampled neighbourhoods are large enough
(200 samples) that every piece holds at least 5 of them (the smallest n = 2 pieces cover about
5 % of the directions), so the counts do not hinge on one sample. Derivative tolerances are
stated where they are used.
"""

from __future__ import annotations

import math
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from biped_opt.analysis.pieces import (
    count_pieces,
    derivative_pieces,
    distinct_gradients,
    leg_inputs,
    offsets_walker,
    simultaneous_rounds,
)
from biped_opt.cli.main import main
from biped_opt.control.derivatives import DEFAULT_VARIATIONAL
from biped_opt.errors import InvalidInputError
from biped_opt.plots.pieces import pieces_figure
from biped_opt.simulation.compiled import compile_system
from biped_opt.simulation.options import DEFAULT_OPTIONS
from biped_opt.systems import walker
from biped_opt.systems.library import biped
from tests.extrapolated import SAFETY, noise_weights


def test_the_offsets_variant_is_opt_in():
    """The library's walkers and the biped keep their coordinates, parameters and maneuvers."""
    for system in (walker(2), biped()):
        assert "clock" not in system.coordinate_names and "d1" not in system.defaults
        assert list(system.maneuvers) == ["touchdown", "liftoff"]
    variant = walker(2, offsets=True)
    assert variant.name == "walker2_coupled_offsets"
    assert list(variant.maneuvers) == ["touchdown", "liftoff", "offsets", "rounds"]
    assert {k: variant.defaults[k] for k in ("d1", "d2", "v1", "v2")} == dict.fromkeys(
        ("d1", "d2", "v1", "v2"), 0.0)


def test_at_zero_offsets_it_is_the_level_touchdown():
    """At s = 0 the offsets maneuver starts where the touchdown maneuver does at th0 = 0 (level
    body, legs vertical at rest length): same outcome and final time. The clock only adds a
    component to the step-size control, so they agree to integration accuracy (1e-9), not
    to rounding."""
    inputs = leg_inputs(2)
    plain = compile_system("walker2_coupled").simulate("touchdown", 0.0, inputs)
    variant = offsets_walker(2)
    variant.set_parameters(d1=0.3, d2=-0.2)  # no effect at s = 0
    mine = variant.simulate("offsets", 0.0, inputs)
    assert plain.success and mine.success
    assert mine.t_final == pytest.approx(plain.t_final, abs=1e-9)
    assert mine.outcome == pytest.approx(plain.outcome, abs=1e-9)
    clock = mine.y_final[len(mine.y_final) // 2 - 1]  # the last coordinate
    assert clock == pytest.approx(mine.t_final, abs=1e-12)
    variant.set_parameters()


def test_rounds_of_the_unperturbed_walker():
    """The dropped walker lands at t = 1 (a fall of z - l0 = 0.5 under g = 1: t = sqrt(2 * 0.5)),
    bounces and lands again. The one-leg walker's second landing would need a pulling ground
    force (its stretched leg pulls the landing foot up), so by complementarity the foot leaves
    the ground at once and lands again: its rounds go on (they ended there, as an
    inconsistency, before the next mode was chosen by complementarity)."""
    two = simultaneous_rounds(2)
    assert [r.kind for r in two] == ["touchdown", "liftoff", "touchdown"]
    assert two[0].t == pytest.approx(1.0, abs=1e-12)
    one = simultaneous_rounds(1)
    assert [r.kind for r in one][:4] == ["touchdown", "liftoff", "touchdown", "touchdown"]
    assert one[0].t == pytest.approx(1.0, abs=1e-12)
    with pytest.raises(InvalidInputError, match="3 simultaneous rounds"):
        count_pieces(2, 4)


@pytest.mark.parametrize(("n", "velocities", "expected"), [
    (1, False, [1, 1]), (1, True, [1, 1]),
    (2, False, [2, 2, 2]), (2, True, [2, 4, 4])])
def test_piece_counts(n, velocities, expected):
    """n = 1: one piece. n = 2, heights only: the pieces are the two touchdown orders for every
    k (one number, d2 - d1, decides every round); with the feet's velocities too the liftoff
    order of round 2 is free, 2 x 2 = 4 = (2!)^2, and round 3 adds none (4 < 8). Every piece's
    boundary is confirmed at a tie of two events."""
    rounds = simultaneous_rounds(n)
    for k, want in enumerate(expected, start=1):
        c = count_pieces(n, k, samples=200, seed=0, velocities=velocities, rounds=rounds)
        assert c.count == want, (k, c.pieces)
        assert c.bound == math.factorial(n) ** k
        assert all(c.confirmed.values()), c.tie_gap
        assert min(c.pieces.values()) >= 5  # each piece sampled several times
    first = count_pieces(n, 1, samples=200, seed=0, rounds=rounds)
    if n == 2:
        assert set(first.pieces) == {"air->foot1->foot1+foot2", "air->foot2->foot1+foot2"}


def test_sampling_until_the_count_stops_growing():
    """Doubled until a doubling adds no piece: ``growth`` records the count at a quarter, half
    and all of the first samples and after every doubling. n = 2, k = 2 with velocities has 4
    pieces, two of them small (10 of 128 samples between them): from 16 samples the count grows
    2, 3, 4 and stops at 128 once a doubling adds none. From 8 samples the first doubling finds
    nothing new and the rule stops at 2: a stable count only excludes pieces larger than about
    3 / m of the directions (m the samples of the last doubling; here 3 / 8), as the
    documentation says; the count is a lower bound."""
    c = count_pieces(2, 2, samples=16, max_samples=1024, seed=0, velocities=True)
    assert c.growth == ((4, 2), (8, 2), (16, 2), (32, 3), (64, 4), (128, 4))
    assert c.stable and c.count == 4 and c.samples == 128 and sum(c.pieces.values()) == 128
    assert c.as_dict()["growth"] == [list(g) for g in c.growth]
    early = count_pieces(2, 2, samples=8, max_samples=1024, seed=0, velocities=True)
    assert early.growth[-2:] == ((8, 2), (16, 2)) and early.stable and early.count == 2
    capped = count_pieces(2, 2, samples=16, max_samples=32, seed=0, velocities=True)
    assert capped.growth[-1] == (32, 3) and not capped.stable  # stopped by max_samples
    with pytest.raises(InvalidInputError, match="max_samples"):
        count_pieces(2, 1, samples=10, max_samples=5)


def test_counts_are_reproducible_from_the_seed():
    a = count_pieces(2, 2, samples=60, seed=7, velocities=True).as_dict()
    b = count_pieces(2, 2, samples=60, seed=7, velocities=True).as_dict()
    assert a == b


def test_bad_arguments_are_one_clear_error():
    with pytest.raises(InvalidInputError, match="n must be an integer in 1..4"):
        count_pieces(5, 1)
    with pytest.raises(InvalidInputError, match="k must be an integer >= 1"):
        count_pieces(2, 0)
    with pytest.raises(InvalidInputError, match="radius"):
        count_pieces(2, 1, radius=0.5)


def _fd_tolerance(p) -> float:
    """SAFETY times the difference quotient's error: its extrapolation's own estimate plus the
    outcomes' integration error (rtol, relative) times the weights of the five-level fit from
    h0 = 1e-3, plus the exact derivative's (the variational rtol, relative)."""
    noise = float(np.abs(noise_weights(1, 1e-3, 5)).sum()) * DEFAULT_OPTIONS.rtol
    return SAFETY * (p.fd_error + noise + DEFAULT_VARIATIONAL.rtol * max(1.0, abs(p.exact)))


def test_linear_pieces_of_the_b_derivative_two_legs():
    """One linear piece per touchdown order, and they differ (the first foot down pushes alone
    for a time proportional to the offsets: force coupling). Each is linear to the accuracy of
    the exact derivatives (1e-8: the variational equation's tolerance), agrees with extrapolated
    difference quotients within their computed error (:func:`_fd_tolerance`), and vanishes on
    the common raise (1, 1), which keeps the motion symmetric and the pitch 0."""
    pieces = derivative_pieces(2, seed=0)
    assert [p.order for p in pieces] == [(1, 2), (2, 1)]
    assert distinct_gradients(pieces) == 2
    assert abs(pieces[0].gradient[0] - pieces[1].gradient[0]) > 0.1
    for p in pieces:
        assert p.exact == pytest.approx(p.linear, abs=1e-8)
        assert p.exact == pytest.approx(p.finite_difference, abs=_fd_tolerance(p))
        assert p.gradient @ np.ones(2) == pytest.approx(0.0, abs=1e-8)


def test_three_legs_every_touchdown_cone_is_linear():
    """n = 3: on every order's cone (taken from the touchdown times, A^-1 tau) g . d is the
    exact derivative (to 1e-8, the variational equation's accuracy) and the finite difference
    (within its computed error, see above); 5 distinct pieces: only the first two feet matter,
    and with the middle foot first (no torque from its hip) not even the second."""
    pieces = derivative_pieces(3, seed=0)
    assert len(pieces) == 6
    for p in pieces:
        assert p.exact == pytest.approx(p.linear, abs=1e-8)
        assert p.exact == pytest.approx(p.finite_difference, abs=_fd_tolerance(p))
    assert distinct_gradients(pieces) == 5
    by_order = {p.order: p.gradient for p in pieces}
    np.testing.assert_allclose(by_order[(2, 1, 3)], by_order[(2, 3, 1)], atol=1e-8)


def test_cli_table_figure_and_json(tmp_path, capsys):
    figure = tmp_path / "pieces.png"
    assert main(["pieces", "--legs", "1", "2", "--rounds", "3", "--samples", "40",
                 "--no-derivative", "--figure", str(figure)]) == 0
    out = capsys.readouterr().out
    assert " 2  2  touchdown, liftoff" in out and " 1  3  touchdown, liftoff, touchdown" in out
    assert figure.stat().st_size > 10_000
    assert main(["pieces", "--legs", "2", "--rounds", "1", "--samples", "20", "--json"]) == 0
    import json

    data = json.loads(capsys.readouterr().out)
    assert [c["count"] for c in data["counts"]] == [2, 2]
    assert [d["order"] for d in data["derivative"]["2"]] == [[1, 2], [2, 1]]


def test_cli_bad_input_is_one_line():
    done = subprocess.run([sys.executable, "-m", "biped_opt.cli.main", "pieces", "--legs", "5"],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 2
    assert done.stderr.strip().count("\n") == 0 and "--legs must be between 1 and 4" in done.stderr


def test_figure_from_plain_records(tmp_path):
    rows = [SimpleNamespace(n=n, k=k, count=c, velocities=v)
            for n, k, c, v in [(2, 1, 2, False), (2, 2, 2, False), (2, 2, 4, True),
                               (3, 1, 6, False)]]
    path = pieces_figure(tmp_path / "p.png", rows, {2: 2, 3: 6})
    assert path.stat().st_size > 10_000
    with pytest.raises(InvalidInputError, match="no counts"):
        pieces_figure(tmp_path / "q.png", [])
