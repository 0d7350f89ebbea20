"""``python -m neuralao.pipeline.cli``: the ``neuralao`` command."""

import sys

from neuralao.pipeline.cli.main import main

sys.exit(main())
