"""`python -m pamjax ...`: the `pamjax` command line (`pamjax._cli.main`)."""

import sys

from ._cli.main import main

sys.exit(main())
