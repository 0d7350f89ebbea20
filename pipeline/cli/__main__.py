"""``python -m pipeline.cli``: the ``neuralao`` command."""

import sys

from pipeline.cli.main import main

sys.exit(main())
