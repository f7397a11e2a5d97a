"""Every case of the `pamjax design` catalogue (`design_cases.py`, issues 29 and 33) ends in a design a bench can play
or one clear named error before any work: no silent wrong result, no traceback, no empty output folder."""

import pytest

from .design_cases import CASES, SLOW, verdict


def test_catalogue_covers_every_class():
    assert {c for c, *_ in CASES.values()} == {"design limits", "design setup", "design outputs"}
    assert len(CASES) >= 15


@pytest.mark.parametrize("name", sorted(set(CASES) - SLOW))
def test_case_ends_in_a_design_or_a_named_error(name):
    result, text = verdict(name)
    assert result == "ok", f"{name}: {result}: {text}"
