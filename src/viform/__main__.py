"""``python -m viform``: the same as the ``viform`` command."""

import sys

from viform.cli import main

sys.exit(main())
