"""Figures of a study table (biped_opt.plots.study) from hand-made rows with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from biped_opt.errors import InvalidInputError
from biped_opt.plots.study import location_plot, locations, size_grid, size_map, study_figures


def _row(point, k, ib, table, quantity, kind, s, size):
    return {"point": str(point), "k": str(k), "Ib": str(ib), "table": table,
            "quantity": quantity, "input": "", "kind": kind, "s": "" if math.isnan(s) else str(s),
            "left": "0", "right": str(size), "size": str(size), "cause": "", "rows": "1"}


ROWS = [
    _row(0, 20, 0.3, "fixed", "outcome", "jump", 0.0, -0.1),
    _row(1, 27, 0.3, "fixed", "outcome", "jump", 0.0, -0.05),
    _row(1, 27, 0.3, "fixed", "outcome", "jump", 0.2, -9.0),  # elsewhere: not at s = 0
    _row(2, 20, 0.5, "fixed", "outcome", "none", math.nan, 0.0),
    _row(3, 27, 0.5, "fixed", "outcome", "jump", 0.0, -0.03),
    _row(0, 20, 0.3, "optimal", "policy", "jump", 0.004, 0.1),
    _row(1, 27, 0.3, "optimal", "policy", "jump", 0.001, 0.1),
    _row(3, 27, 0.5, "optimal", "policy", "jump", 0.002, 0.1),
]


def test_size_grid_puts_each_point_in_its_cell_and_marks_absence() -> None:
    xs, ys, sizes = size_grid(ROWS, "k", "Ib")
    assert list(xs) == [20, 27] and list(ys) == [0.3, 0.5]
    assert sizes[0].tolist() == [-0.1, -0.05]  # the jump at s = 0.2 is not the one at 0
    assert math.isnan(sizes[1, 0]) and sizes[1, 1] == -0.03


def test_locations_by_second_parameter() -> None:
    found = locations(ROWS, "k", by="Ib")
    assert list(found) == [0.3, 0.5]
    np.testing.assert_array_equal(found[0.3][0], [20, 27])
    np.testing.assert_array_equal(found[0.3][1], [0.004, 0.001])


def test_figures_are_written(tmp_path) -> None:
    paths = study_figures(tmp_path, ROWS, ["k", "Ib"])
    names = sorted(p.name for p in paths)
    assert names == ["map_fixed_outcome_jump.png", "policy_jump_location.png"]
    import matplotlib.image as mpimg

    # the figures' sizes (6.4 x 4.8 and 6.4 x 4.0 inches) at the writer's 150 dpi
    shapes = [mpimg.imread(p).shape[:2] for p in sorted(paths)]
    assert shapes == [(720, 960), (600, 960)]
    assert size_map(tmp_path / "m.png", ROWS, "k", "Ib").exists()
    assert location_plot(tmp_path / "l.png", ROWS, "k").exists()


def test_a_parameter_the_study_did_not_vary() -> None:
    with pytest.raises(InvalidInputError, match="did not vary 'w'"):
        size_grid(ROWS, "k", "w")
    with pytest.raises(InvalidInputError, match="no rows"):
        size_grid([], "k", "Ib")
