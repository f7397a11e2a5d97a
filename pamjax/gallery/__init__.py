"""The paper gallery's toolkit (`fits/papers/`, run by `pamjax reproduce`): what a reproduction script returns
(`Result` of `Row`s), how it writes figures (`plt`, `save`), the `fits/` procedures it reuses (`fits_module`), the
bench recordings (`bench_folder`), and running one script on its own (`script_main`)."""

from ._cli.reproduce import (
    Result as Result,
    Row as Row,
    bench_folder as bench_folder,
    fits_module as fits_module,
    plt as plt,
    save as save,
    script_main as script_main,
)
