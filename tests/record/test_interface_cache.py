"""The parsed interface definitions kept in the cache
(:class:`biped_opt.interface_defs.Definitions`): read back exactly as parsed, parsed again when
a file changes or the kept copy is damaged, and never needed for a definition to load."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

import biped_opt.interface_defs as defs_module
from biped_opt.interface_defs import Definitions, find_msg_defs

SWEEP = "biped_opt_interfaces/msg/SweepPoint"


@pytest.fixture()
def parses(monkeypatch, tmp_path):
    """A private cache and a count of the parses done (each a call of the parser)."""
    monkeypatch.setenv("BIPED_OPT_CACHE", str(tmp_path / "cache"))
    count = {"parses": 0}
    real = defs_module._parse

    def counted(files):
        count["parses"] += 1
        return real(files)

    monkeypatch.setattr(defs_module, "_parse", counted)
    return count


def _same(a: Definitions, b: Definitions) -> None:
    assert a.msg_names == b.msg_names and a.srv_names == b.srv_names
    assert a.action_names == b.action_names and a.field_defaults == b.field_defaults
    assert a.typestore.fielddefs == b.typestore.fielddefs  # (tuples stay tuples: == tells)


def test_a_second_process_reads_back_what_the_first_parsed(parses):
    root = find_msg_defs()
    first = Definitions(root)
    assert parses["parses"] == 1 and len(list(defs_module.parsed_cache().glob("*.json"))) == 1
    second = Definitions(root)
    assert parses["parses"] == 1
    _same(first, second)


def test_a_changed_definition_is_parsed_again(parses, tmp_path):
    root = tmp_path / "msg_defs"
    shutil.copytree(find_msg_defs(), root)
    before = Definitions(root)
    path = root / "msg" / "SweepPoint.msg"
    path.write_text(path.read_text() + "\nfloat64 added_field\n")
    after = Definitions(root)
    assert parses["parses"] == 2
    fields = [name for name, _ in after.typestore.fielddefs[SWEEP][1]]
    assert fields[-1] == "added_field"
    assert "added_field" not in [name for name, _ in before.typestore.fielddefs[SWEEP][1]]


@pytest.mark.parametrize("damage", ["", "{", '{"types": {}}', '{"types": [1], "msg_names": 3}'])
def test_a_damaged_kept_parse_is_parsed_again_and_replaced(parses, damage):
    root = find_msg_defs()
    parsed = Definitions(root)
    (kept,) = defs_module.parsed_cache().glob("*.json")
    kept.write_text(damage)
    again = Definitions(root)
    assert parses["parses"] == 2
    _same(parsed, again)
    Definitions(root)
    assert parses["parses"] == 2  # (the damaged file was replaced)


def test_an_unwritable_cache_costs_only_the_parse(parses, monkeypatch, tmp_path):
    blocker = tmp_path / "not_a_directory"
    blocker.write_text("")
    monkeypatch.setenv("BIPED_OPT_CACHE", str(blocker))
    root = find_msg_defs()
    _same(Definitions(root), Definitions(root))
    assert parses["parses"] == 2
    assert Path(blocker).read_text() == ""
