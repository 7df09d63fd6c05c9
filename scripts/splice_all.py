#!/usr/bin/env python
"""Splice every n x m combination of a database into a new database.

The same as ``torchsplice splice-all``; see ``python scripts/splice_all.py --help``.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from torchsplice.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["splice-all", *sys.argv[1:]]))
