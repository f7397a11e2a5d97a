"""`python -m pamjax ...`: the `pamjax` command line (`pamjax._cli`)."""

import sys

from ._cli import main

sys.exit(main())
