"""``python -m mjx_arm.babble``: the babbling command line (`mjx_arm.babble.cli.main`)."""

import sys

from mjx_arm.babble.cli import main

if __name__ == "__main__":
    sys.exit(main())
