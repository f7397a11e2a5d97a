"""Every catalogued bad input raises `PamjaxInputError` naming the offending field, before any solve."""

import pytest

import pamjax

from .bad_inputs import CORE_CASES


def test_catalogue_is_large():
    assert len(CORE_CASES) >= 30


@pytest.mark.parametrize("case", sorted(CORE_CASES))
def test_bad_input_is_named(case):
    make, name = CORE_CASES[case]
    with pytest.raises(pamjax.PamjaxInputError) as info:
        make()
    assert name in str(info.value), f"{case}: message does not name {name!r}: {info.value}"
