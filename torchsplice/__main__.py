"""``python -m torchsplice``: the same as the ``torchsplice`` command."""

import sys

from .cli import main

sys.exit(main())
