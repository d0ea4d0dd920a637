"""The search options of /query and /similar: one parser, and it accepts what the schema
documents (the modalities' pattern) and nothing else."""

from __future__ import annotations

import re
from types import SimpleNamespace

import pytest

from app.errors import ConflictError, InvalidInputError
from app.search.service import MODALITIES_PATTERN, parse_options
from worker.engine.presets import get_preset

STATE = SimpleNamespace(settings=SimpleNamespace(max_k=100))
GALLERY = SimpleNamespace(name="default", preset=get_preset("smeets2010-shrec"))


def options(**fields: str | None):
    values = {"k": None, "preset": None, "fusion": None, "modalities": None} | fields
    return parse_options(STATE, GALLERY, **values)


@pytest.mark.parametrize(
    "text",
    ["", "   ", "gdm", "gdm,ddt", " gdm , ddt ", "gdm,,ddt", "gdm,", ",spectrum", " , ",
     "gdm ddt", "gdmddt", "colour", "gdm,colour", "\t", "GDM"],
)  # fmt: skip
def test_modalities_are_accepted_exactly_when_the_documented_pattern_matches(text):
    documented = re.search(MODALITIES_PATTERN, text) is not None
    try:
        options(modalities=text)
        accepted = True
    except InvalidInputError as error:
        assert error.code == "unknown_modality"
        accepted = False
    assert accepted == documented, text


def test_blank_options_are_the_defaults():
    chosen = options(k=" ", preset="", fusion="  ", modalities="")
    assert chosen.k == 10 and chosen.preset.name == "smeets2010-shrec"
    assert chosen.fusion is None and chosen.modalities == ("gdm", "ddt")
    assert options(modalities=" spectrum , gdm,gdm").modalities == ("spectrum", "gdm")


@pytest.mark.parametrize(
    ("fields", "code"),
    [
        ({"k": "0"}, "invalid_k"),
        ({"k": "101"}, "invalid_k"),
        ({"k": "2.5"}, "invalid_k"),
        ({"fusion": "max"}, "invalid_fusion"),
        ({"preset": "nope"}, "unknown_preset"),
    ],
)
def test_bad_options_are_refused_with_their_code(fields, code):
    with pytest.raises(InvalidInputError) as error:
        options(**fields)
    assert error.value.code == code and error.value.detail.endswith(".")


def test_another_known_preset_conflicts_with_the_collections():
    """A collection's routes document every preset (a collection may have been created
    with another); naming one that is not the collection's is a conflict, 409."""
    with pytest.raises(ConflictError) as error:
        options(preset="lb-spectrum")
    assert error.value.code == "preset_not_enrolled" and error.value.status == 409
    assert "'smeets2010-shrec'" in error.value.detail
