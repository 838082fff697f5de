"""``python -m experiments.cli``: the ``sgatwalk`` command."""

import sys

from experiments.cli import main

sys.exit(main())
