"""``python -m fusiongs <verb> ...``: the same as the ``fusiongs`` command."""

import sys

from fusiongs.cli import main

sys.exit(main())
