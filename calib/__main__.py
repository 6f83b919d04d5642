"""``python -m calib``: the command line for measured data (calib.cli)."""

import sys

from calib.cli.commands import main

if __name__ == "__main__":
    sys.exit(main())
