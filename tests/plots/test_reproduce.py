"""The reproduction end to end on small grids: files, captions, and the marks' numbers."""

from __future__ import annotations

import pytest

from biped_opt.plots.reproduce import reproduce


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    return reproduce(tmp_path_factory.mktemp("figs"), fixed_num=41, optimal_num=21)


def test_writes_three_pngs_and_captions(result):
    for path in result.figures:
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert path.stat().st_size > 20_000  # a drawn figure, not an empty canvas
    text = result.captions.read_text()
    assert "k = 27" in text and "th_star" in text.replace("theta_star", "th_star")
    assert "jump" in text and "kink" in text


def test_table_has_the_papers_points(result):
    """Fixed inputs: touchdown kink and liftoff jump at 0 with MODEL.md's one-sided numbers
    (1e-6: the table's extrapolation is good to ~1e-8)."""
    fixed = {r.subject: r for r in result.reports if not r.optimal}
    (kink,) = [p for p in fixed["touchdown"].points if p.quantity == "outcome"]
    assert kink.kind == "kink" and kink.theta0 == 0.0
    assert abs(kink.left - 0.796243869) < 1e-6 and abs(kink.right - 0.714366448) < 1e-6
    (jump,) = [p for p in fixed["liftoff"].points if p.quantity == "outcome"]
    assert jump.kind == "jump"
    assert abs(jump.left - 0.026283950) < 1e-7 and abs(jump.right + 0.006532702) < 1e-7
    optimal = {r.subject: r for r in result.reports if r.optimal}
    kinds = {(p.quantity, p.kind) for p in optimal["liftoff"].points}
    assert ("policy", "jump") in kinds and ("value", "kink") in kinds
    assert any(p.quantity == "value" and p.kind == "jump"
               for p in optimal["liftoff-variant"].points)
