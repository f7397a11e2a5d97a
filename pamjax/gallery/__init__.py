"""The paper gallery (`pamjax reproduce`): one script per figure, table or experiment of papers 000 and 001
(`pamjax.gallery.scripts`), the catalogue of every item of both papers with its status computed from the numbers
(`pamjax.gallery.catalogue`), the procedures of `fits/` the scripts reuse (`pamjax.gallery.procedures`), the index
page and `docs/papers.md` written from them (`pamjax.gallery.report`, `pamjax.gallery.docs`).

The toolkit a script uses: `Result` (and `Row`), `plt`, `save`, `bench_folder` / `bench_params` (the hybrid bench's
recordings, shipped in `pamjax/data/hybrid-reference-bench`), `script_main` (run one script on its own), and
`json_text` (strict JSON of a report: a non-finite number as the text "inf" / "nan", as pamjax's result files
write it).
"""

from .._core.jsonio import json_text as json_text
from .toolkit import (
    Result as Result,
    Row as Row,
    bench_folder as bench_folder,
    bench_params as bench_params,
    fits_module as fits_module,
    plt as plt,
    refuse_existing as refuse_existing,
    save as save,
    script_main as script_main,
)
