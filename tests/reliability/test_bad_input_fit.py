"""Every catalogued bad input of the fitting workflow raises a pamjax error naming the offending field, before any
solve; existing results files are never replaced without `overwrite` (see `bad_inputs_fit.py`)."""

import pytest

import pamjax

from .bad_inputs_fit import FILE_CASES, FIT_CASES


def test_catalogue_is_large():
    assert len(FIT_CASES) >= 30


@pytest.mark.parametrize("case", sorted(FIT_CASES))
def test_bad_fit_input_is_named(case):
    make, name = FIT_CASES[case]
    with pytest.raises(ValueError) as info:
        make()
    assert name in str(info.value), f"{case}: message does not name {name!r}: {info.value}"
    assert isinstance(info.value, pamjax.PamjaxInputError), f"{case}: {type(info.value)}"


@pytest.mark.parametrize("case", sorted(FILE_CASES))
def test_existing_file_is_not_replaced(case):
    with pytest.raises(FileExistsError, match="overwrite"):
        FILE_CASES[case]()
