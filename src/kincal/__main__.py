"""``python -m kincal``: the command line."""

import sys

from kincal.cli.main import main

if __name__ == "__main__":
    sys.exit(main())
